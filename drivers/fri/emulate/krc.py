"""The KRC between FRI and the simulated arm: which command fields it takes, what it reports.

Pure functions, no I/O. The FRI emulator over UDP and the in-process lockstep
robot both use them, so the world sees the same arm command for the same FRI
command, and the remote sees the same measurement for the same world state.

* :func:`arm_command_from_fri`: the KRC takes the fields ``cmdFlags`` selects
  (the others keep their previous values) and switches to the requested
  strategy;
* :func:`stop_command`: what the KRC does when it leaves command mode: hold
  the measured pose, no superposed wrench or torque;
* :func:`fri_measurement`: the ``tFriMsrData`` of a world state, with the
  link's state, quality and statistics (:func:`measurement_head` and
  :func:`measurement_of`: the same in two parts, the first kept while the link
  does not change);
* :func:`plausible_command`: values a KRC would take (beyond them it leaves
  command mode);
* :func:`software_limit_error` and :func:`brake_command`: the software limit
  switches. A joint that reaches its limit makes the KRC leave command mode
  and stop the robot (:meth:`~drivers.fri.link.KrcLink.fault`): the arm is
  held where it is (modelled as the joint position controller holding the
  measured joints, stiff as the scene's ``jnt_position_stiffness``: the
  brakes), and the measurement reports the error until it is acknowledged.
  Source: Schreiber, Stemmer, Bischoff, "The Fast Research Interface for the
  KUKA Lightweight Robot" (ICRA 2010 workshop, sec. V): when command values
  hit limits the KRC "falls back to monitor mode, stopping the robot if
  necessary".
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import fields
from typing import Final

import numpy as np

from drivers.base.types import F64
from drivers.description.lwr4 import LWR4
from drivers.errors import InvalidCommandError
from drivers.fri.types import (
    WARN_POSITION_LIMIT,
    WARN_STIFFNESS_CLIPPED,
    WARN_TORQUE_LIMIT,
    WARN_VELOCITY_LIMIT,
    CmdFlags,
    ControlMode,
    FriCommand,
    FriMeasurement,
    FriQuality,
    FriState,
)
from drivers.world.arm import ArmCommand, ArmMode, ArmState, ArmWarning

__all__ = [
    "HARDWARE_LIMITS_DEG",
    "MAX_DAMPING",
    "MAX_JNT_TRQ_NM",
    "MAX_REACH_M",
    "MAX_STIFFNESS",
    "MAX_TCP_FORCE_N",
    "MAX_TCP_TORQUE_NM",
    "SOFTWARE_LIMITS_DEG",
    "CommandDelay",
    "StateMeasurement",
    "arm_command_from_fri",
    "arm_mode",
    "brake_command",
    "control_mode",
    "fri_measurement",
    "fri_warning",
    "measurement_head",
    "measurement_of",
    "plausible_command",
    "software_limit_error",
    "software_limits_rad",
    "state_free_head",
    "stop_command",
]

_TO_ARM: Final = {
    ControlMode.JOINT_POSITION: ArmMode.JOINT_POSITION,
    ControlMode.CART_IMPEDANCE: ArmMode.CART_IMPEDANCE,
    ControlMode.JOINT_IMPEDANCE: ArmMode.JOINT_IMPEDANCE,
}
_TO_FRI: Final = {v: k for k, v in _TO_ARM.items()}
_WARNINGS: Final = (
    (int(ArmWarning.STIFFNESS_CLIPPED), WARN_STIFFNESS_CLIPPED),
    (int(ArmWarning.TORQUE_LIMIT), WARN_TORQUE_LIMIT),
    (int(ArmWarning.VELOCITY_LIMIT), WARN_VELOCITY_LIMIT),
    (int(ArmWarning.POSITION_LIMIT), WARN_POSITION_LIMIT),
)
#: Temperature the emulated drives report [deg C].
DRIVE_TEMPERATURE_C: Final = 30.0


def _constant(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a


#: A measurement's fields that never change (the arrays read-only, shared by every
#: measurement), in field order; :func:`fri_measurement` starts from a copy of it.
_CONSTANT_FIELDS: Final = {
    name: value.copy() if isinstance(value, list) else value
    for name, value in vars(FriMeasurement(
        temperature=_constant(np.full(7, DRIVE_TEMPERATURE_C)),
        cmd_jnt_pos_fri_offset=_constant(np.zeros(7)),
        cmd_cart_pos_fri_offset=_constant(np.eye(4)),
        krl_real=_constant(np.zeros(16)),
        krl_int=_constant(np.zeros(16, dtype=np.int32)),
    )).items()
}
_new: Final = object.__new__
#: The fields :func:`measurement_of` sets from the world state, each cycle.
_STATE_FIELDS: Final = ("seq", "time_ns", "control", "warning", "msr_jnt_pos", "msr_cart_pos",
                        "cmd_jnt_pos", "cmd_cart_pos", "msr_jnt_trq", "est_ext_jnt_trq",
                        "est_ext_tcp_ft", "jacobian", "mass_matrix", "gravity", "link_events")
#: :data:`_CONSTANT_FIELDS` with ``None`` in the fields of a state (not read: replaced;
#: cheaper to replace than the defaults' own objects).
_HEAD: Final = {name: None if name in _STATE_FIELDS else value
                for name, value in _CONSTANT_FIELDS.items()}

#: Hardware (mechanical) joint ranges of the LWR4+ A1..A7 [deg]: +-170/120
#: (CentroEPiaggio kuka-lwr URDF; the KRC's rsidef7.dat as quoted by TUM's
#: kuka_fri FRICheck.cc), the range of the simulated joints.
HARDWARE_LIMITS_DEG: Final = LWR4.position_limits_deg
#: The KRC's software limit switches A1..A7 [deg]: +-160/110, the "safety soft
#: limits" of an older CentroEPiaggio kuka-lwr URDF (commit 00915b5), 10 deg
#: inside the hardware ranges. A real cell's values are in its machine data;
#: set them per emulator (``software_limits_deg``).
SOFTWARE_LIMITS_DEG: Final = (160.0, 110.0, 160.0, 110.0, 160.0, 110.0, 160.0)


def arm_mode(control: ControlMode) -> ArmMode:
    """The arm mode of an FRI control mode; OTHER is refused (:class:`InvalidCommandError`)."""
    mode = _TO_ARM.get(control)
    if mode is None:
        raise InvalidCommandError(f"control mode {control!r} not supported")
    return mode


def control_mode(mode: ArmMode) -> ControlMode:
    """The FRI control mode an arm mode reports."""
    return _TO_FRI[mode]


def _fri_warning(w: int) -> int:
    out = 0
    for arm_bit, fri_bit in _WARNINGS:
        if w & arm_bit:
            out |= fri_bit
    return out


# the FRI bits of every combination of the arm's warning bits (a lookup per cycle)
_FRI_WARNINGS: Final = tuple(_fri_warning(w) for w in range(1 << len(_WARNINGS)))


def fri_warning(warning: ArmWarning) -> int:
    """The FRI warning bits of the arm's warnings."""
    w = int(warning)
    return _FRI_WARNINGS[w] if w < len(_FRI_WARNINGS) else _fri_warning(w)


# the flags as plain ints: ``int & IntFlag`` goes through the enum machinery (slow)
_CARTPOS, _CARTSTIFF, _CARTDAMP, _TCPFT = (int(CmdFlags.CARTPOS), int(CmdFlags.CARTSTIFF),
                                          int(CmdFlags.CARTDAMP), int(CmdFlags.TCPFT))
_JNTPOS, _JNTTRQ, _JNTSTIFF, _JNTDAMP = (int(CmdFlags.JNTPOS), int(CmdFlags.JNTTRQ),
                                        int(CmdFlags.JNTSTIFF), int(CmdFlags.JNTDAMP))
_EYE3 = np.eye(3)


def arm_command_from_fri(cmd: FriCommand, current: ArmMode) -> ArmCommand:
    """The fields of ``cmd`` its flags select, as an arm command (arrays shared, not copied).

    ``current`` is the arm's running mode: a request of another mode is a
    switch; OTHER is refused with :class:`InvalidCommandError`.
    """
    f = int(cmd.flags)
    mode = current if cmd.control == control_mode(current) else arm_mode(cmd.control)
    return ArmCommand(
        mode=mode,
        cart_pose_m=cmd.cart_pos if f & _CARTPOS else None,
        cart_stiffness_npm_nmprad=cmd.cart_stiffness if f & _CARTSTIFF else None,
        cart_damping_ratio=cmd.cart_damping if f & _CARTDAMP else None,
        tcp_wrench_n_nm=cmd.add_tcp_ft if f & _TCPFT else None,
        jnt_pos_rad=cmd.jnt_pos if f & _JNTPOS else None,
        jnt_trq_nm=cmd.add_jnt_trq if f & _JNTTRQ else None,
        jnt_stiffness_nmprad=cmd.jnt_stiffness if f & _JNTSTIFF else None,
        jnt_damping_ratio=cmd.jnt_damping if f & _JNTDAMP else None,
    )


class CommandDelay:
    """The KRC's command timing: a remote's answer to measurement k acts from cycle k + ``cycles``.

    A real KRC sends measurement k, the remote computes and answers within
    the cycle, and the KRC applies the answer at its next cycle at the
    earliest (Schreiber et al., ICRA 2010 workshop, sec. V-B: above a 1 ms
    cycle it fine-interpolates the commands over the following cycle). The
    lockstep world steps cycle k right after the answer to measurement k,
    so ``cycles = 0`` is a command acting within the cycle it answers and
    ``cycles = 1`` the real KRC's earliest (scene key ``fri.command_delay_cycles``).

    Each cycle's entry is the arm command the KRC takes from the remote, or
    ``None`` (no answer, not commanding: bridged, the world holds what it
    has). Commands of the KRC itself (a stop, the brakes) act at once and
    discard what was in flight (:meth:`clear`). The in-process lockstep robot
    and the lockstep UDP emulator both use this one class, so a run over UDP
    equals the in-process run bit for bit; in real-time pacing the link's own
    timing is the delay and none is added.

    Args:
        cycles: whole cycles between a measurement and the first cycle its
            answer acts in (0: the same cycle).
    """

    def __init__(self, cycles: int) -> None:
        if cycles < 0:
            raise ValueError(f"command delay must be >= 0 cycles, got {cycles}")
        self.cycles = cycles
        self.queue: deque[tuple[ArmCommand | None, int | None]] = deque()
        """The commands in flight, oldest first, with their sequence numbers (always
        ``cycles`` of them: :meth:`push` appends one and takes the oldest)."""
        self.clear()

    def clear(self) -> None:
        """Nothing in flight: the next ``cycles`` cycles act on no remote command."""
        self.queue.clear()
        self.queue.extend([(None, None)] * self.cycles)

    def push(self, arm: ArmCommand | None, seq: int | None = None, *, copy: bool = True
             ) -> tuple[ArmCommand | None, int | None]:
        """Hand in this cycle's answer (with its sequence number, if any); returns the
        one that acts in this cycle. A delayed command is copied (the caller's arrays
        are reused by the next answer), unless ``copy`` is false: the caller then keeps
        its arrays unchanged until the command has acted (``cycles`` cycles later)."""
        if not self.cycles:
            return arm, seq
        queue = self.queue
        queue.append((_owned(arm) if copy and arm is not None else arm, seq))
        return queue.popleft()


#: The array fields of an arm command (every field but its mode).
_ARM_ARRAYS: Final = tuple(f.name for f in fields(ArmCommand) if f.name != "mode")


def _owned(arm: ArmCommand) -> ArmCommand:
    """``arm`` with arrays of its own (``copy.copy`` and a copy of each array, without
    the copy module's protocol: one dictionary copied)."""
    d = arm.__dict__.copy()
    for name in _ARM_ARRAYS:
        v = d[name]
        if v is not None:
            d[name] = np.array(v)
    out = _new(type(arm))
    out.__dict__ = d
    return out


def software_limits_rad(limits_deg: Sequence[float]) -> F64:
    """Validated software limits [rad]: 7 angles, each in (0, hardware range).

    Raises:
        ValueError: naming ``software_limits_deg``.
    """
    lim = np.asarray(limits_deg, dtype=np.float64)
    if lim.shape != (7,) or not np.all((lim > 0.0) & (lim < np.asarray(HARDWARE_LIMITS_DEG))):
        raise ValueError(f"software_limits_deg: 7 angles [deg] in (0, {HARDWARE_LIMITS_DEG}), "
                         f"got {tuple(limits_deg)}")
    return np.radians(lim)


def software_limit_error(jnt_pos_rad: F64, limits_rad: F64) -> int:
    """Error bits (:data:`~drivers.fri.link.ERROR_SOFTWARE_LIMIT`) of the joints at or
    beyond their software limit (``|q_i| >= limit_i``); 0 when none is."""
    # most cycles no joint is near: plain floats are cheaper than numpy for 7 values
    if not any(map(float.__ge__, map(abs, jnt_pos_rad[:7].tolist()), limits_rad.tolist())):
        return 0
    hit = np.abs(jnt_pos_rad[:7]) >= limits_rad
    return int(np.sum(1 << np.flatnonzero(hit)))


def brake_command(state: ArmState) -> ArmCommand:
    """The KRC stops the robot: hold the measured joints in joint position mode (the
    brakes), no superposed torque."""
    return ArmCommand(
        mode=ArmMode.JOINT_POSITION,
        jnt_pos_rad=state.jnt_pos_rad.copy(),
        jnt_trq_nm=np.zeros(7),
    )


def stop_command(state: ArmState) -> ArmCommand:
    """Leaving command mode: hold the measured pose and joints, no superposed wrench or torque."""
    return ArmCommand(
        mode=state.mode,
        cart_pose_m=state.tcp_pose_m.copy(),
        tcp_wrench_n_nm=np.zeros(6),
        jnt_pos_rad=state.jnt_pos_rad.copy(),
        jnt_trq_nm=np.zeros(7),
    )


def measurement_head(cycle_s: float, state: FriState, quality: FriQuality, error: int = 0,
                     rates: tuple[float, float, float, float] | None = None,
                     miss_counter: int = 0) -> dict[str, object]:
    """The fields of a measurement that do not come from the world state, by name in
    field order: the constants, the link's ``state``, ``quality``, ``error`` and (when
    given) its ``(answer_rate, latency_s, jitter_s, miss_rate)`` and ``miss_counter``,
    the sample times. :func:`measurement_of` adds a world state's; a KRC whose link
    did not change reuses it."""
    d = _HEAD.copy()
    d["state"] = state
    d["quality"] = quality
    d["msr_sample_time"] = cycle_s
    d["cmd_sample_time"] = cycle_s
    if rates is not None:
        d["answer_rate"], d["latency_s"], d["jitter_s"], d["miss_rate"] = rates
        d["miss_counter"] = miss_counter
    d["error"] = error
    return d


def measurement_of(head: dict[str, object], s: ArmState) -> FriMeasurement:
    """The measurement of world state ``s`` with the fields of ``head``
    (:func:`measurement_head`; arrays shared with ``s``, not copied)."""
    # built without the dataclass's __init__ (its 30 arguments): a copy of the head,
    # then the fields of this cycle (the same field order and values; one by one is
    # cheaper than an update from a zip)
    d = head.copy()
    d["seq"] = s.cycle
    d["time_ns"] = s.time_ns
    d["control"] = _TO_FRI[s.mode]
    w = int(s.warning)
    d["warning"] = _FRI_WARNINGS[w] if w < len(_FRI_WARNINGS) else _fri_warning(w)
    d["msr_jnt_pos"] = s.jnt_pos_rad
    d["msr_cart_pos"] = s.tcp_pose_m
    d["cmd_jnt_pos"] = s.cmd_jnt_pos_rad
    d["cmd_cart_pos"] = s.cmd_cart_pose_m
    d["msr_jnt_trq"] = s.jnt_trq_nm
    d["est_ext_jnt_trq"] = s.ext_jnt_trq_nm
    d["est_ext_tcp_ft"] = s.ext_wrench_n_nm
    d["jacobian"] = s.jacobian
    d["mass_matrix"] = s.mass_matrix
    d["gravity"] = s.gravity_nm
    d["link_events"] = []
    m: FriMeasurement = _new(FriMeasurement)
    m.__dict__ = d
    return m


class StateMeasurement(FriMeasurement):
    """:func:`measurement_of` built lazily: the fields of the link (the head's) are set
    now, those of the world state (:data:`_STATE_FIELDS` but ``link_events``) are read
    from :attr:`arm_state` on the first read of any of them, all at once, with the values
    :func:`measurement_of` gives (a lockstep KRC's recording that keeps only the link
    pays nothing for them). Equal to the :class:`FriMeasurement` of the same values."""

    __slots__ = ("arm_state",)
    arm_state: ArmState

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, FriMeasurement):
            return NotImplemented
        return _compared(self) == _compared(other)

    __hash__ = None  # type: ignore[assignment]  # (as the dataclass's: mutable)


class _FromState:
    """A field of :class:`StateMeasurement` not read yet: reading it fills them all."""

    __slots__ = ("name",)

    def __init__(self, name: str) -> None:
        self.name = name

    def __get__(self, m: StateMeasurement | None, owner: type | None = None) -> object:
        if m is None:  # (the class's attribute: the dataclass field's default, if any)
            return getattr(FriMeasurement, self.name, None)
        s = m.arm_state
        w = int(s.warning)
        values = (s.cycle, s.time_ns, _TO_FRI[s.mode],
                  _FRI_WARNINGS[w] if w < len(_FRI_WARNINGS) else _fri_warning(w),
                  s.jnt_pos_rad, s.tcp_pose_m, s.cmd_jnt_pos_rad, s.cmd_cart_pose_m,
                  s.jnt_trq_nm, s.ext_jnt_trq_nm, s.ext_wrench_n_nm, s.jacobian,
                  s.mass_matrix, s.gravity_nm)
        d = m.__dict__
        for name, value in zip(_LAZY_FIELDS, values, strict=True):
            d.setdefault(name, value)  # (a field set since keeps its value)
        return d[self.name]


#: The fields :class:`StateMeasurement` reads from its state (measurement_of's order).
_LAZY_FIELDS: Final = _STATE_FIELDS[:-1]
for _name in _LAZY_FIELDS:
    setattr(StateMeasurement, _name, _FromState(_name))
_COMPARED: Final = tuple(f.name for f in fields(FriMeasurement) if f.compare)


def _compared(m: FriMeasurement) -> tuple[object, ...]:
    return tuple(getattr(m, name) for name in _COMPARED)


def state_free_head(head: dict[str, object]) -> dict[str, object]:
    """``head`` (:func:`measurement_head`) without the fields of a world state: the
    dictionary a :class:`StateMeasurement` starts from (add a new ``link_events``)."""
    return {name: value for name, value in head.items() if name not in _STATE_FIELDS}


def fri_measurement(
    s: ArmState,
    cycle_s: float,
    state: FriState,
    quality: FriQuality,
    error: int = 0,
) -> FriMeasurement:
    """The measurement packet of a world state (arrays shared with ``s``, not copied).

    ``error``: the KRC's latched error bits (:class:`~drivers.fri.link.KrcLink`).

    Link statistics (answer rate, latency, ...) are left at their defaults;
    the UDP emulator fills them from its window. The fields the emulated KRC
    never changes (temperatures, FRI offsets, the KRL variables) are read-only
    arrays shared by every measurement.
    """
    return measurement_of(measurement_head(cycle_s, state, quality, error), s)


#: Largest command values the emulated KRC takes (beyond them it leaves command mode).
MAX_TCP_FORCE_N: Final = 1000.0
MAX_TCP_TORQUE_NM: Final = 200.0
MAX_JNT_TRQ_NM: Final = 500.0
MAX_REACH_M: Final = 2.0
MAX_STIFFNESS: Final = 1.0e5
MAX_DAMPING: Final = 10.0


def plausible_command(c: FriCommand) -> bool:
    """Whether the fields ``c.flags`` selects are values a KRC would take.

    Finite, forces/torques and stiffnesses within generous bounds, a proper
    rotation in ``cart_pos`` within reach, joint angles within a turn.
    """
    f = int(c.flags)
    if f & _CARTPOS:
        p = c.cart_pos
        r = p[:3, :3]
        if not (np.isfinite(p).all() and np.abs(p[:3, 3]).max() <= MAX_REACH_M
                and np.abs(r.T @ r - _EYE3).max() <= 1e-3):
            return False
    if f & _JNTPOS and not (np.abs(c.jnt_pos) <= 2.0 * math.pi).all():
        return False
    if f & _TCPFT:
        w = c.add_tcp_ft
        if not (np.abs(w[:3]).max() <= MAX_TCP_FORCE_N
                and np.abs(w[3:]).max() <= MAX_TCP_TORQUE_NM):
            return False
    if f & _JNTTRQ and not np.abs(c.add_jnt_trq).max() <= MAX_JNT_TRQ_NM:
        return False
    for flag, gains, top in (
        (_CARTSTIFF, c.cart_stiffness, MAX_STIFFNESS),
        (_JNTSTIFF, c.jnt_stiffness, MAX_STIFFNESS),
        (_CARTDAMP, c.cart_damping, MAX_DAMPING),
        (_JNTDAMP, c.jnt_damping, MAX_DAMPING),
    ):
        if f & flag and not (gains.min() >= 0.0 and gains.max() <= top):
            return False
    return True
