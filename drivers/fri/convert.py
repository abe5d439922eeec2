"""Between :mod:`drivers.fri.types` objects and the codec's packet arrays, both sides of the link.

The codec (:mod:`drivers.fri.codec`) already converts the wire layout to our
conventions; this module only copies between its preallocated
:class:`~drivers.fri.codec.MsrArrays` / :class:`~drivers.fri.codec.CmdArrays`
and :class:`~drivers.fri.types.FriMeasurement` / :class:`~drivers.fri.types.FriCommand`.

Two conventions of ffexp on top of FRI 1.x live here (docs/guides/krc.md, the KRL
side):

* **Control strategy request.** FRI 1.x has no command field for the
  controller. The remote writes the requested KRL strategy into
  ``krl.intData[0]`` (``$FRI_FRM_INT[1]``): 10 joint position, 20 Cartesian
  impedance, 30 joint impedance, 0 = no request. The KRL script switches
  ``$stiffness.strategy`` when it differs from the running one.
* **Lockstep marker (emulator only).** In lockstep pacing the emulator sets
  ``krl.intData[15]`` (``$FRI_TO_INT[16]``) to :data:`LOCKSTEP_MARKER`; the
  remote driver then answers each cycle with the runner's command for that
  cycle, however long the runner takes, so that lockstep runs are
  deterministic. A real KRC never sets it unless a KRL script writes this
  value there.
"""

from __future__ import annotations

import dataclasses
from typing import Final

import numpy as np

from drivers.fri.codec import CmdArrays, MsrArrays
from drivers.fri.types import CmdFlags, ControlMode, FriCommand, FriMeasurement

__all__ = [
    "LOCKSTEP_INDEX",
    "LOCKSTEP_MARKER",
    "STRATEGY_INDEX",
    "arrays_to_command",
    "arrays_to_measurement",
    "command_to_arrays",
    "control_from_strategy",
    "copy_measurement",
    "cycle_ns_from_seconds",
    "fill_measurement",
    "measurement_to_arrays",
    "strategy_code",
]

#: ``krl.intData`` index (``$FRI_FRM_INT[1]``) that carries the requested KRL strategy.
STRATEGY_INDEX: Final = 0
#: ``krl.intData`` index (``$FRI_TO_INT[16]``) of the emulator's lockstep marker.
LOCKSTEP_INDEX: Final = 15
#: Value of ``$FRI_TO_INT[16]`` that marks a lockstep emulator ("LOCK" in ASCII).
LOCKSTEP_MARKER: Final = 0x4C4F434B

_STRATEGY: Final = {
    ControlMode.JOINT_POSITION: 10,
    ControlMode.CART_IMPEDANCE: 20,
    ControlMode.JOINT_IMPEDANCE: 30,
}
_CONTROL: Final = {v: k for k, v in _STRATEGY.items()}


def strategy_code(control: ControlMode) -> int:
    """KRL ``$stiffness.strategy`` for ``control`` (0 for OTHER: no request)."""
    return _STRATEGY.get(ControlMode(control), 0)


def control_from_strategy(code: int) -> ControlMode | None:
    """The control mode a strategy request asks for; ``None`` for 0 or an unknown code."""
    return _CONTROL.get(int(code))


def cycle_ns_from_seconds(seconds: float) -> int:
    """A sample time from the wire (float32 seconds) in whole microseconds, as ns.

    ``float32(0.005)`` is 0.00499999988...; the KRC's cycles are whole
    milliseconds, so rounding to the microsecond recovers the exact value.
    """
    return round(float(seconds) * 1e6) * 1000


def measurement_to_arrays(m: FriMeasurement, out: MsrArrays) -> None:
    """Fill ``out`` from ``m`` (the emulator side); head counters are left alone."""
    out.krl_real[...] = m.krl_real
    out.krl_int[...] = m.krl_int
    out.krl_bool = int(m.krl_bool)
    out.timestamp = m.time_ns * 1e-9
    out.state = m.state
    out.quality = m.quality
    out.msr_sample_time = m.msr_sample_time
    out.cmd_sample_time = m.cmd_sample_time
    out.safety_limits = m.safety_limits
    out.answer_rate = m.answer_rate
    out.latency = m.latency_s
    out.jitter = m.jitter_s
    out.miss_rate = m.miss_rate
    out.miss_counter = int(m.miss_counter)
    out.power = int(m.power)
    out.control = m.control
    out.error = int(m.error)
    out.warning = int(m.warning)
    out.temperature[...] = m.temperature
    out.msr_jnt_pos[...] = m.msr_jnt_pos
    out.msr_cart_pos[...] = m.msr_cart_pos
    out.cmd_jnt_pos[...] = m.cmd_jnt_pos
    out.cmd_jnt_pos_fri_offset[...] = m.cmd_jnt_pos_fri_offset
    out.cmd_cart_pos[...] = m.cmd_cart_pos
    out.cmd_cart_pos_fri_offset[...] = m.cmd_cart_pos_fri_offset
    out.msr_jnt_trq[...] = m.msr_jnt_trq
    out.est_ext_jnt_trq[...] = m.est_ext_jnt_trq
    out.est_ext_tcp_ft[...] = m.est_ext_tcp_ft
    out.jacobian[...] = m.jacobian
    out.mass_matrix[...] = m.mass_matrix
    out.gravity[...] = m.gravity


def arrays_to_measurement(a: MsrArrays, seq: int, time_ns: int) -> FriMeasurement:
    """A new :class:`FriMeasurement` (own copies) from decoded arrays (the remote side).

    ``seq`` is the unwrapped ``sendSeqCount``, ``time_ns`` the cycle's time.
    """
    m = FriMeasurement()
    fill_measurement(a, seq, time_ns, m)
    return m


def fill_measurement(a: MsrArrays, seq: int, time_ns: int, m: FriMeasurement) -> None:
    """Fill ``m`` in place (no allocation) from decoded arrays (:func:`arrays_to_measurement`)."""
    m.seq = seq
    m.time_ns = time_ns
    m.state = a.state
    m.quality = a.quality
    m.control = a.control
    m.msr_sample_time = a.msr_sample_time
    m.cmd_sample_time = a.cmd_sample_time
    m.safety_limits = a.safety_limits
    m.answer_rate = a.answer_rate
    m.latency_s = a.latency
    m.jitter_s = a.jitter
    m.miss_rate = a.miss_rate
    m.miss_counter = a.miss_counter
    m.power = a.power
    m.error = a.error
    m.warning = a.warning
    m.temperature[...] = a.temperature
    m.msr_jnt_pos[...] = a.msr_jnt_pos
    m.msr_cart_pos[...] = a.msr_cart_pos
    m.cmd_jnt_pos[...] = a.cmd_jnt_pos
    m.cmd_jnt_pos_fri_offset[...] = a.cmd_jnt_pos_fri_offset
    m.cmd_cart_pos[...] = a.cmd_cart_pos
    m.cmd_cart_pos_fri_offset[...] = a.cmd_cart_pos_fri_offset
    m.msr_jnt_trq[...] = a.msr_jnt_trq
    m.est_ext_jnt_trq[...] = a.est_ext_jnt_trq
    m.est_ext_tcp_ft[...] = a.est_ext_tcp_ft
    m.jacobian[...] = a.jacobian
    m.mass_matrix[...] = a.mass_matrix
    m.gravity[...] = a.gravity
    m.krl_real[...] = a.krl_real
    m.krl_int[...] = a.krl_int
    m.krl_bool = a.krl_bool


def copy_measurement(src: FriMeasurement, dst: FriMeasurement) -> None:
    """Copy every field of ``src`` into ``dst`` in place (arrays element-wise, no
    allocation); both of the same class (a :class:`~drivers.fri.types.RemoteMeasurement`
    carries its counters along). ``link_events`` is not copied."""
    for name in _fields(type(src)):
        value = getattr(src, name)
        if isinstance(value, np.ndarray):
            getattr(dst, name)[...] = value
        else:
            setattr(dst, name, value)


_FIELDS: dict[type, tuple[str, ...]] = {}


def _fields(cls: type) -> tuple[str, ...]:
    names = _FIELDS.get(cls)
    if names is None:
        names = _FIELDS[cls] = tuple(
            f.name for f in dataclasses.fields(cls) if f.name != "link_events")
    return names


def command_to_arrays(c: FriCommand, out: CmdArrays) -> None:
    """Fill ``out`` from ``c`` (the remote side); the strategy goes to ``krl.intData[0]``."""
    out.cmd_flags = int(c.flags)
    out.jnt_pos[...] = c.jnt_pos
    out.cart_pos[...] = c.cart_pos
    out.add_jnt_trq[...] = c.add_jnt_trq
    out.add_tcp_ft[...] = c.add_tcp_ft
    out.jnt_stiffness[...] = c.jnt_stiffness
    out.jnt_damping[...] = c.jnt_damping
    out.cart_stiffness[...] = c.cart_stiffness
    out.cart_damping[...] = c.cart_damping
    out.krl_real[...] = c.krl_real
    out.krl_int[...] = c.krl_int
    out.krl_int[STRATEGY_INDEX] = strategy_code(c.control)
    out.krl_bool = int(c.krl_bool) & 0xFFFF


def arrays_to_command(a: CmdArrays, current: ControlMode) -> FriCommand:
    """A new :class:`FriCommand` from a decoded packet (the emulator side).

    The control mode is the strategy requested in ``krl.intData[0]``, or
    ``current`` when there is no (valid) request.
    """
    control = control_from_strategy(int(a.krl_int[STRATEGY_INDEX]))
    return FriCommand(
        flags=CmdFlags(a.cmd_flags & 0xFFFFFFFF),
        control=current if control is None else control,
        jnt_pos=a.jnt_pos.copy(),
        cart_pos=a.cart_pos.copy(),
        add_jnt_trq=a.add_jnt_trq.copy(),
        add_tcp_ft=a.add_tcp_ft.copy(),
        jnt_stiffness=a.jnt_stiffness.copy(),
        jnt_damping=a.jnt_damping.copy(),
        cart_stiffness=a.cart_stiffness.copy(),
        cart_damping=a.cart_damping.copy(),
        krl_real=a.krl_real.copy(),
        krl_int=a.krl_int.copy(),
        krl_bool=a.krl_bool,
    )
