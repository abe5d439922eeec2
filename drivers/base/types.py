"""Data exchanged with the robot and the F/T sensor, in ffexp's conventions.

Plain dataclasses holding numpy arrays (no validation per cycle). They carry
the fields of an FRI 1.x measurement / command packet one to one, converted
to our conventions (``../shared/design/CONVENTIONS.md``):

* poses are 4x4 homogeneous matrices (FRI: 12 floats, row-major 3x4);
* wrenches are ``[fx, fy, fz, tx, ty, tz]`` in the TCF, SI units (FRI sends
  ``[Fx, Fy, Fz, Tz, Ty, Tx]``);
* Cartesian stiffness/damping are ``[x, y, z, rx, ry, rz]`` (FRI:
  ``[x, y, z, A(rz), B(ry), C(rx)]``);
* the Jacobian is 6x7 with rows ``[vx, vy, vz, wx, wy, wz]`` in the TCF (FRI
  rows ``[X, Y, Z, RZ, RY, RX]``);
* a measured wrench is the wrench the environment exerts on the tool.

The UDP codec (a later issue) does the reordering; nothing else changes.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum, IntFlag

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]


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


class FtStatus(IntFlag):
    """Net F/T RDT status word bits (0 = healthy); see the fact sheet."""

    OK = 0
    MONITOR_LATCHED = 0x00010000
    SATURATION = 0x00020000
    ERROR = 0x80000000


#: Bits of :attr:`Measurement.warning` that the simulator sets.
WARN_STIFFNESS_CLIPPED = 0x0001
WARN_TORQUE_LIMIT = 0x0002
WARN_VELOCITY_LIMIT = 0x0004
WARN_POSITION_LIMIT = 0x0008


@dataclass
class GroundTruth:
    """What only a simulator knows, attached to a measurement (``None`` on hardware).

    World frame: z up, the bed plane is horizontal.
    """

    target_pose: F64 = field(default_factory=_eye4)
    """4x4 pose of the target block's centre in the world frame."""
    target_twist: F64 = field(default_factory=lambda: _zeros(3))
    """``[vx, vy, wz]`` of the target in the world frame [m/s, rad/s]."""
    contact_wrench: F64 = field(default_factory=lambda: _zeros(6))
    """True wrench the target funnel exerts on the tool, TCF at the TCP."""
    lateral_error: float = 0.0
    """Tool tip offset from the target funnel axis, horizontal [m] (signed, funnel y)."""
    vertical_error: float = 0.0
    """Tool tip offset from the funnel axis along the vertical [m]."""
    yaw_error: float = 0.0
    """Tool axis yaw minus funnel axis yaw [rad], wrapped to (-pi, pi]."""
    insertion: float = 0.0
    """Tool tip depth past the funnel mouth along the funnel axis [m]."""
    seated: bool = False
    in_contact: bool = False
    tcp_twist: F64 = field(default_factory=lambda: _zeros(6))
    """True TCP twist ``[v, w]`` in the TCF."""


@dataclass
class Measurement:
    """One FRI measurement packet (``tFriMsrData``) in our conventions."""

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
    latency: float = 0.0
    jitter: float = 0.0
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
    truth: GroundTruth | None = None


@dataclass
class Command:
    """One FRI command packet (``tFriCmdData``) in our conventions.

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

    @classmethod
    def hold(cls, m: Measurement) -> Command:
        """Mirror the KRC: command where it already is (FRI's rule while not commanding)."""
        return cls(
            flags=CmdFlags.JNTPOS | CmdFlags.CARTPOS,
            control=m.control,
            jnt_pos=m.cmd_jnt_pos + m.cmd_jnt_pos_fri_offset,
            cart_pos=m.cmd_cart_pos.copy(),
        )


@dataclass
class FtSamples:
    """F/T samples since the last read, oldest first.

    ``wrench`` is the sensor's reading in our sign convention (the wrench the
    environment exerts on the tool, TCF, referred to the TCP), *including* the
    sensor's bias and the tool's gravity and inertia load, like a real Net F/T
    after its tool transform. Compensation is the estimator's job.
    """

    time_ns: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    seq: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    wrench: F64 = field(default_factory=lambda: np.zeros((0, 6)))
    status: NDArray[np.uint32] = field(default_factory=lambda: np.zeros(0, dtype=np.uint32))

    def __len__(self) -> int:
        return int(self.time_ns.shape[0])

    @classmethod
    def concat(cls, parts: list[FtSamples]) -> FtSamples:
        if not parts:
            return cls()
        if len(parts) == 1:
            return parts[0]
        return cls(
            time_ns=np.concatenate([p.time_ns for p in parts]),
            seq=np.concatenate([p.seq for p in parts]),
            wrench=np.concatenate([p.wrench for p in parts]),
            status=np.concatenate([p.status for p in parts]),
        )
