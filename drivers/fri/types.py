"""FRI 1.x packet contents in ffexp's conventions: states, flags, measurement, command.

What only FRI has lives here, not in :mod:`drivers.base`. The dataclasses
carry the fields of ``tFriMsrData`` / ``tFriCmdData`` one to one, converted
to our conventions (``docs/conventions.md``):

* poses are 4x4 homogeneous matrices (FRI: 12 floats, row-major 3x4);
* wrenches are ``[fx, fy, fz, tx, ty, tz]`` in the TCF, SI units (FRI sends
  ``[Fx, Fy, Fz, Tz, Ty, Tx]``);
* Cartesian stiffness/damping are ``[x, y, z, rx, ry, rz]`` (FRI:
  ``[x, y, z, A(rz), B(ry), C(rx)]``);
* the Jacobian is 6x7 with rows ``[vx, vy, vz, wx, wy, wz]`` in the TCF (FRI
  rows ``[X, Y, Z, RZ, RY, RX]``);
* a measured wrench is the wrench the environment exerts on the tool.

The UDP codec (:mod:`drivers.fri.codec`) does the reordering.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum, IntFlag

import numpy as np
from numpy.typing import NDArray

from drivers.base.types import F64, Extras


def _zeros(n: int) -> F64:
    return np.zeros(n, dtype=np.float64)


def _eye4() -> F64:
    return np.eye(4, dtype=np.float64)


class FriState(IntEnum):
    """``intf.state`` (friComm FRI_STATE)."""

    INVALID = -1
    OFF = 0
    MON = 1
    CMD = 2


class FriQuality(IntEnum):
    """``intf.quality`` (friComm FRI_QUALITY). BAD, OK and PERFECT allow commanding."""

    INVALID = -1
    UNACCEPTABLE = 0
    BAD = 1
    OK = 2
    PERFECT = 3


class ControlMode(IntEnum):
    """``robot.control`` (friComm FRI_CTRL); the KRL strategy is 10/20/30 for 1/2/3."""

    OTHER = 0
    JOINT_POSITION = 1
    CART_IMPEDANCE = 2
    JOINT_IMPEDANCE = 3


class CmdFlags(IntFlag):
    """``cmd.cmdFlags``: which command fields the KRC takes this cycle (friComm)."""

    NONE = 0
    JNTPOS = 0x0001
    JNTTRQ = 0x0004
    JNTSTIFF = 0x0010
    JNTDAMP = 0x0020
    CARTPOS = 0x0100
    TCPFT = 0x0400
    CARTSTIFF = 0x1000
    CARTDAMP = 0x2000


#: Bits of :attr:`FriMeasurement.warning` that the simulator sets.
WARN_STIFFNESS_CLIPPED = 0x0001
WARN_TORQUE_LIMIT = 0x0002
WARN_VELOCITY_LIMIT = 0x0004
WARN_POSITION_LIMIT = 0x0008


@dataclass
class FriMeasurement(Extras):
    """One FRI measurement packet (``tFriMsrData``) in our conventions.

    Carried as :attr:`drivers.base.RobotState.extras` by the FRI-speaking
    back-ends; recorded on ``/robot/measurement`` and ``/robot/link``.
    """

    seq: int = 0
    """``head.sendSeqCount`` (uint16 on the wire, unbounded here)."""
    time_ns: int = 0
    """Time of the cycle [ns] (sim time, or KRC ``intf.timestamp``)."""
    state: FriState = FriState.CMD
    quality: FriQuality = FriQuality.PERFECT
    control: ControlMode = ControlMode.CART_IMPEDANCE
    msr_sample_time: float = 0.005
    cmd_sample_time: float = 0.005
    safety_limits: float = 1.0
    answer_rate: float = 1.0
    latency_s: float = 0.0
    jitter_s: float = 0.0
    miss_rate: float = 0.0
    miss_counter: int = 0
    power: int = 0x7F
    error: int = 0
    warning: int = 0
    temperature: F64 = field(default_factory=lambda: _zeros(7))
    msr_jnt_pos: F64 = field(default_factory=lambda: _zeros(7))
    msr_cart_pos: F64 = field(default_factory=_eye4)
    cmd_jnt_pos: F64 = field(default_factory=lambda: _zeros(7))
    cmd_jnt_pos_fri_offset: F64 = field(default_factory=lambda: _zeros(7))
    cmd_cart_pos: F64 = field(default_factory=_eye4)
    cmd_cart_pos_fri_offset: F64 = field(default_factory=_eye4)
    msr_jnt_trq: F64 = field(default_factory=lambda: _zeros(7))
    est_ext_jnt_trq: F64 = field(default_factory=lambda: _zeros(7))
    """External joint torques the environment exerts [N m]."""
    est_ext_tcp_ft: F64 = field(default_factory=lambda: _zeros(6))
    """External wrench on the tool estimated from joint torques, TCF at the TCP."""
    jacobian: F64 = field(default_factory=lambda: np.zeros((6, 7)))
    mass_matrix: F64 = field(default_factory=lambda: np.zeros((7, 7)))
    gravity: F64 = field(default_factory=lambda: _zeros(7))
    krl_real: F64 = field(default_factory=lambda: _zeros(16))
    krl_int: NDArray[np.int32] = field(default_factory=lambda: np.zeros(16, dtype=np.int32))
    krl_bool: int = 0
    link_events: list[tuple[int, str, str, str]] = field(
        default_factory=list, compare=False, repr=False)
    """Changes of the link seen up to this measurement that the runner has not yet
    been told about: ``(KRC time [ns], level, name, message)``; :meth:`take_events`
    clears it."""

    def topics(self) -> tuple[str, ...]:
        return ("/robot/measurement", "/robot/link")

    def take_events(self) -> list[tuple[int, str, str, str]]:
        events = list(self.link_events)
        self.link_events.clear()
        return events


@dataclass
class RemoteMeasurement(FriMeasurement):
    """A measurement as the UDP remote driver received it, with the driver's own
    link counters at its arrival (cumulative since ``connect``), recorded on
    ``/robot/link_driver`` beside the KRC's own view (``/robot/link``)."""

    received: int = 0
    """Datagrams received on the port, any source."""
    foreign: int = 0
    """Datagrams from an address other than the robot's, dropped."""
    foreign_ipv4: int = 0
    """The last foreign sender's IPv4 address as a 32-bit number (0: none yet)."""
    foreign_port: int = 0
    """The last foreign sender's UDP port (0: none yet)."""
    rejected: int = 0
    """Datagrams from the robot the codec rejected (short, wrong id, bad sizes)."""
    accepted: int = 0
    """Measurements accepted (new sequence numbers)."""
    lost: int = 0
    """Measurements missing in the sequence and never received late."""
    duplicates: int = 0
    """Measurements received again (re-answered, not passed on)."""
    reordered: int = 0
    """Measurements that came after a newer one (dropped)."""
    restarts: int = 0
    """Sequence jumps back taken as a KRC restart."""
    implausible: int = 0
    """Measurements with impossible contents (dropped)."""
    answers: int = 0
    """Command datagrams sent (including re-answers of duplicates)."""
    runner_answers: int = 0
    """Cycles answered with the runner's command of that very cycle."""
    deadline_answers: int = 0
    """Cycles answered at the deadline with the previous command (runner late)."""
    runner_late: int = 0
    """Runner commands that came after their cycle had been answered."""
    skipped: int = 0
    """Measurements the runner never saw (it fell behind)."""
    turnaround_s: float = 0.0
    """Packet received -> answer sent, the last answered cycle."""

    def topics(self) -> tuple[str, ...]:
        return ("/robot/measurement", "/robot/link", "/robot/link_driver")


@dataclass
class FriCommand(Extras):
    """One FRI command packet (``tFriCmdData``) in our conventions (recorded on ``/robot/command``).

    Only the fields selected by :attr:`flags` are taken, as on the KRC; the
    others keep their previous value. :attr:`control` is the strategy the
    KRL script switches to (carried in ``krl.intData`` by the UDP codec).
    """

    flags: CmdFlags = CmdFlags.NONE
    control: ControlMode = ControlMode.CART_IMPEDANCE
    jnt_pos: F64 = field(default_factory=lambda: _zeros(7))
    cart_pos: F64 = field(default_factory=_eye4)
    add_jnt_trq: F64 = field(default_factory=lambda: _zeros(7))
    add_tcp_ft: F64 = field(default_factory=lambda: _zeros(6))
    jnt_stiffness: F64 = field(default_factory=lambda: _zeros(7))
    jnt_damping: F64 = field(default_factory=lambda: _zeros(7))
    cart_stiffness: F64 = field(default_factory=lambda: _zeros(6))
    cart_damping: F64 = field(default_factory=lambda: _zeros(6))
    krl_real: F64 = field(default_factory=lambda: _zeros(16))
    krl_int: NDArray[np.int32] = field(default_factory=lambda: np.zeros(16, dtype=np.int32))
    krl_bool: int = 0

    def topics(self) -> tuple[str, ...]:
        return ("/robot/command",)

    @classmethod
    def hold(cls, m: FriMeasurement) -> FriCommand:
        """Mirror the KRC: command where it already is (FRI's rule while not commanding)."""
        return cls(
            flags=CmdFlags.JNTPOS | CmdFlags.CARTPOS,
            control=m.control,
            jnt_pos=m.cmd_jnt_pos + m.cmd_jnt_pos_fri_offset,
            cart_pos=m.cmd_cart_pos.copy(),
        )
