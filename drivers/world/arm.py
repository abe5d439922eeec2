"""What the simulated LWR4+ takes and reports, in the world's own terms (no link protocol).

The arm's controller (the KRC's, modelled in :mod:`drivers.base.impedance`)
runs in one of three modes and latches the set-points and gains it is given;
what it is not given it keeps. :class:`ArmCommand` says which fields are
given this cycle (``None`` = keep). How a link protocol selects fields (FRI's
``cmdFlags``) is the emulator's business (:mod:`drivers.emulate`), not the
world's.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum, IntFlag

import numpy as np

from drivers.base.types import F64, GroundTruth

__all__ = ["ArmCommand", "ArmMode", "ArmState", "ArmWarning"]


class ArmMode(IntEnum):
    """The arm controller's modes (the KRL strategies 10, 20, 30)."""

    JOINT_POSITION = 1
    CART_IMPEDANCE = 2
    JOINT_IMPEDANCE = 3


class ArmWarning(IntFlag):
    """Warning bits of an :class:`ArmState`."""

    NONE = 0
    STIFFNESS_CLIPPED = 0x0001
    """A commanded stiffness was beyond the arm's limits and was clipped."""
    TORQUE_LIMIT = 0x0002
    """A joint's actuator torque is at its limit."""
    VELOCITY_LIMIT = 0x0004
    """A joint moves faster than its limit."""
    POSITION_LIMIT = 0x0008
    """A joint is within 1 mrad of its range."""


@dataclass
class ArmCommand:
    """One cycle's command to the arm controller: the fields given are latched.

    ``mode`` switches the controller (``None``: keep the running mode; a switch
    first resets both set-points to where the arm is). Every other field is
    ``None`` (keep the latched value) or an array in ffexp's conventions:
    poses 4x4 in the base frame [m], Cartesian gains and wrench per TCF axis
    ``[x, y, z, rx, ry, rz]``, damping normalised (0..1).
    """

    mode: ArmMode | None = None
    cart_pose_m: F64 | None = None
    cart_stiffness_npm_nmprad: F64 | None = None
    cart_damping_ratio: F64 | None = None
    tcp_wrench_n_nm: F64 | None = None
    """Superposed wrench at the TCP, TCF [N, N m]."""
    jnt_pos_rad: F64 | None = None
    jnt_trq_nm: F64 | None = None
    """Superposed joint torques [N m]."""
    jnt_stiffness_nmprad: F64 | None = None
    jnt_damping_ratio: F64 | None = None


def _zeros(n: int) -> F64:
    return np.zeros(n, dtype=np.float64)


@dataclass
class ArmState:
    """The arm at the end of a cycle, as its controller and sensors know it (plus the truth).

    Arrays are owned by this object (the world does not change them later).
    """

    cycle: int = 0
    time_ns: int = 0
    mode: ArmMode = ArmMode.CART_IMPEDANCE
    jnt_pos_rad: F64 = field(default_factory=lambda: _zeros(7))
    tcp_pose_m: F64 = field(default_factory=lambda: np.eye(4))
    cmd_jnt_pos_rad: F64 = field(default_factory=lambda: _zeros(7))
    """The joint set-point in use (in Cartesian impedance: the measured joints)."""
    cmd_cart_pose_m: F64 = field(default_factory=lambda: np.eye(4))
    """The Cartesian set-point in use (in joint modes: the measured pose)."""
    jnt_trq_nm: F64 = field(default_factory=lambda: _zeros(7))
    """Link-side torque sensors."""
    ext_jnt_trq_nm: F64 = field(default_factory=lambda: _zeros(7))
    """External joint torques the environment exerts."""
    ext_wrench_n_nm: F64 = field(default_factory=lambda: _zeros(6))
    """External wrench on the tool, TCF at the TCP (exact: no model error)."""
    jacobian: F64 = field(default_factory=lambda: np.zeros((6, 7)))
    """6x7, rows ``[vx, vy, vz, wx, wy, wz]`` in the TCF."""
    mass_matrix: F64 = field(default_factory=lambda: np.zeros((7, 7)))
    gravity_nm: F64 = field(default_factory=lambda: _zeros(7))
    warning: ArmWarning = ArmWarning.NONE
    truth: GroundTruth = field(default_factory=GroundTruth)
