"""An arm's description: its kinematic chain, joint limits and link inertias. Pure maths.

One :class:`ArmDescription` per arm model (:data:`drivers.description.lwr4.LWR4`); the
simulator builds its model from it, the emulated controller takes its limits from it and
``ffexp.scene3d`` draws the arm by its forward kinematics.

The chain, in the URDF's convention: frame ``link{i}`` sits at ``joint_origins_m[i-1]`` in
its parent (``link{i-1}``, the arm's base for ``link1``), turned by ``joint_rpy_rad[i-1]``
(roll, pitch, yaw about the parent's x, y, z: ``Rz(yaw) Ry(pitch) Rx(roll)``; none for the
LWR4+), and turns by joint ``i`` about ``joint_axes[i-1]`` (a unit axis of the link frame).
The flange sits at ``flange_m`` (turned by ``flange_rpy_rad``) in the last link's frame.
An arm published as standard Denavit-Hartenberg parameters (the UR robots) is written in
this form by :func:`dh_chain`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from drivers.base.types import F64
from drivers.config import Vec3

__all__ = ["ArmDescription", "DhChain", "dh_chain", "rpy_matrix"]

_ZERO: Vec3 = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class ArmDescription:
    """One arm model's published numbers, per joint or link ``1..n`` in order.

    Attributes:
        name: the model's name (``"KUKA LWR4+"``).
        joint_origins_m: each joint's frame origin in its parent link's frame [m].
        joint_axes: each joint's axis in its own link frame (``+-x``, ``+-y``, ``+-z``).
        position_limits_deg: joint position limits [deg]: the upper ones, and the lower
            ones too negated unless ``position_lower_deg`` gives them.
        velocity_limits_degps: joint speed limits [deg/s].
        link_masses_kg: link masses [kg].
        link_coms_m: link centres of mass in the link frame [m].
        link_inertias_kgm2: principal moments of inertia about the link axes [kg m^2].
        joint_rpy_rad: each joint frame's fixed rotation in its parent at zero angle
            (roll, pitch, yaw [rad]); None: none (the parent's axes).
        flange_m: the flange's origin in the last link's frame [m].
        flange_rpy_rad: the flange's rotation in the last link's frame (roll, pitch, yaw).
        rotor_inertias_kgm2: each drive's reflected rotor inertia [kg m^2] (None: not
            published).
        drive_coulomb_nm: each drive's identified Coulomb friction [N m] (None: not published).
        drive_viscous_nmsprad: each drive's identified viscous friction [N m s/rad] (None:
            not published).
        link_coulomb_nm, link_viscous_nmsprad: friction identified after the joint torque
            sensors (what a torque loop does not reduce) [N m], [N m s/rad] (None: none).
        position_lower_deg: lower joint position limits of an arm whose ranges are not
            symmetric [deg] (None: ``-position_limits_deg``).
    """

    name: str
    joint_origins_m: tuple[Vec3, ...]
    joint_axes: tuple[tuple[int, int, int], ...]
    position_limits_deg: tuple[float, ...]
    velocity_limits_degps: tuple[float, ...]
    link_masses_kg: tuple[float, ...]
    link_coms_m: tuple[Vec3, ...]
    link_inertias_kgm2: tuple[Vec3, ...]
    joint_rpy_rad: tuple[Vec3, ...] | None = None
    flange_m: Vec3 = _ZERO
    flange_rpy_rad: Vec3 = _ZERO
    rotor_inertias_kgm2: tuple[float, ...] | None = None
    drive_coulomb_nm: tuple[float, ...] | None = None
    drive_viscous_nmsprad: tuple[float, ...] | None = None
    link_coulomb_nm: tuple[float, ...] | None = None
    link_viscous_nmsprad: tuple[float, ...] | None = None
    position_lower_deg: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        n = len(self.joint_origins_m)
        for name in ("joint_axes", "position_limits_deg", "velocity_limits_degps",
                     "link_masses_kg", "link_coms_m", "link_inertias_kgm2", "joint_rpy_rad",
                     "rotor_inertias_kgm2", "drive_coulomb_nm", "drive_viscous_nmsprad",
                     "link_coulomb_nm", "link_viscous_nmsprad", "position_lower_deg"):
            values = getattr(self, name)
            if values is not None and len(values) != n:
                raise ValueError(f"{self.name}: {name} has {len(values)} entries for {n} joints")
        for axis in self.joint_axes:
            if sorted(abs(a) for a in axis) != [0, 0, 1]:
                raise ValueError(f"{self.name}: joint axis {axis} is not a unit axis of the link")

    @property
    def joints(self) -> int:
        """Number of joints."""
        return len(self.joint_origins_m)

    @property
    def lower_limits_deg(self) -> tuple[float, ...]:
        """The lower joint position limits [deg]."""
        if self.position_lower_deg is not None:
            return self.position_lower_deg
        return tuple(-v for v in self.position_limits_deg)

    def joint_transforms(self, q_rad: Sequence[float] | F64) -> list[F64]:
        """Each link's pose in its parent at joint positions ``q_rad`` (4x4 each)."""
        if len(q_rad) != self.joints:
            raise ValueError(f"{len(q_rad)} joint positions; the {self.name} has {self.joints}")
        out = []
        for origin, turn, axis, q in zip(self.joint_origins_m, self._fixed_turns,
                                         self.joint_axes, q_rad, strict=True):
            t = np.eye(4)
            t[:3, 3] = origin
            t[:3, :3] = turn @ _axis_rotation(axis, float(q))
            out.append(t)
        return out

    @cached_property
    def _fixed_turns(self) -> tuple[F64, ...]:
        """Each joint frame's fixed rotation matrix (:func:`rpy_matrix` of
        ``joint_rpy_rad``, identity without), computed once per description."""
        rpy = self.joint_rpy_rad or (_ZERO,) * self.joints
        return tuple(rpy_matrix(turn) for turn in rpy)

    def flange_pose(self, q_rad: Sequence[float] | F64) -> F64:
        """The flange's pose in the arm's base frame at joint positions ``q_rad``."""
        pose = np.eye(4)
        for t in self.joint_transforms(q_rad):
            pose = pose @ t
        flange = np.eye(4)
        flange[:3, 3] = self.flange_m
        flange[:3, :3] = rpy_matrix(self.flange_rpy_rad)
        return pose @ flange


def rpy_matrix(rpy: Sequence[float]) -> F64:
    """``Rz(yaw) Ry(pitch) Rx(roll)`` (the URDF's fixed-axis roll, pitch, yaw) [rad]."""
    roll, pitch, yaw = (float(v) for v in rpy)
    return _axis_rotation((0, 0, 1), yaw) @ _axis_rotation((0, 1, 0), pitch) \
        @ _axis_rotation((1, 0, 0), roll)


def _axis_rotation(axis: Sequence[int], angle_rad: float) -> F64:
    """The rotation by ``angle_rad`` about a signed unit axis of the frame."""
    k = [abs(a) for a in axis].index(1)
    c, s = math.cos(angle_rad), math.sin(angle_rad) * axis[k]
    i, j = (k + 1) % 3, (k + 2) % 3
    out = np.eye(3)
    out[i, i], out[i, j], out[j, i], out[j, j] = c, -s, s, c
    return out


@dataclass(frozen=True)
class DhChain:
    """A standard Denavit-Hartenberg chain in :class:`ArmDescription`'s form."""

    joint_origins_m: tuple[Vec3, ...]
    joint_rpy_rad: tuple[Vec3, ...]
    flange_m: Vec3
    flange_rpy_rad: Vec3


def dh_chain(a_m: Sequence[float], d_m: Sequence[float],
             alpha_rad: Sequence[float]) -> DhChain:
    """Standard DH parameters (``Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)`` per joint, all
    joints about their z) as joint origins and rotations: joint 1 at the base, joint ``i``
    at ``(a, 0, d)`` of joint ``i-1`` turned by ``alpha`` about x, the flange likewise after
    the last joint. A link's frame here is the DH frame before its ``Tz Tx Rx``: a centre of
    mass given in the DH frame ``i`` maps to ``Tz(d_i) Tx(a_i) Rx(alpha_i)`` of it."""
    if not len(a_m) == len(d_m) == len(alpha_rad):
        raise ValueError(f"DH parameters of unequal lengths: a {len(a_m)}, d {len(d_m)}, "
                         f"alpha {len(alpha_rad)}")
    fixed = [((float(a), 0.0, float(d)), (float(al), 0.0, 0.0))
             for a, d, al in zip(a_m, d_m, alpha_rad, strict=True)]
    return DhChain(
        joint_origins_m=(_ZERO, *(f[0] for f in fixed[:-1])),
        joint_rpy_rad=(_ZERO, *(f[1] for f in fixed[:-1])),
        flange_m=fixed[-1][0],
        flange_rpy_rad=fixed[-1][1],
    )
