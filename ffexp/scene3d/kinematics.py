"""Forward kinematics of the KUKA LWR4+ with the rig's sensor and tool. Pure, no I/O.

The chain is the published one the simulator is built from
(:data:`drivers.description.lwr4.LWR4`, an :class:`~drivers.description.arm.ArmDescription`):
frame ``link{i}`` sits at ``joint_origins_m[i-1]`` (along the z axis) of its parent
(``link{i-1}``, the base for ``link1``) and turns by joint ``i`` about its
axis (``+z`` or ``-y``/``+y`` of the link). The flange is ``link7``'s origin;
the F/T sensor and the tool follow along its z axis, and the TCF (the tool
tip) is the flange frame moved ``sensor_height + shaft_length + funnel.depth``
along z and turned by 180 deg about it (as the simulator's model, :mod:`drivers.sim.mjcf`).

The rotations about a coordinate axis are written out: a 4x4 from ``cos`` and
``sin`` costs a few microseconds where ``scipy``'s ``Rotation`` costs tens.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from drivers.base.types import F64
from drivers.description import LWR4, Scene, tool_tip_offset
from drivers.description.arm import Vec3

__all__ = ["JOINTS", "flange_to_tcp", "link_rows", "link_transforms", "translation"]

#: Joints of the LWR4+.
JOINTS = LWR4.joints
_ORIGINS = LWR4.joint_origins_m
_AXES = LWR4.joint_axes


def translation(x: float, y: float, z: float) -> F64:
    """A 4x4 translation."""
    out = np.eye(4)
    out[:3, 3] = (x, y, z)
    return out


def _joint(origin_m: Vec3, axis: Sequence[int], angle_rad: float) -> F64:
    """``Trans(origin) Rot(axis, angle)`` for an axis of +-z or +-y."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    out = np.eye(4)
    out[:3, 3] = origin_m
    if axis[2]:
        s *= axis[2]
        out[0, 0], out[0, 1], out[1, 0], out[1, 1] = c, -s, s, c
    elif axis[1]:
        s *= axis[1]
        out[0, 0], out[0, 2], out[2, 0], out[2, 2] = c, s, -s, c
    else:
        raise ValueError(f"joint axis {tuple(axis)}: only +-y and +-z are used by the LWR4+")
    return out


def link_transforms(q_rad: Sequence[float] | F64, base: F64 | None = None) -> list[F64]:
    """Pose of every ``link{i}`` (i = 1..7) in its parent (``base``'s frame for
    ``link1``, which includes ``base``, the arm's base in the robot's frame)."""
    if len(q_rad) < JOINTS:
        raise ValueError(f"{len(q_rad)} joint positions; the LWR4+ has {JOINTS}")
    out = [_joint(_ORIGINS[i], _AXES[i], float(q_rad[i])) for i in range(JOINTS)]
    if base is not None:
        out[0] = base @ out[0]
    return out


def _joint_rows(origin_m: Vec3, axis: Sequence[int], angle_rad: float) -> list[list[float]]:
    """:func:`_joint` as its rows of floats (the same values, without numpy)."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    x, y, z = (float(v) for v in origin_m)
    if axis[2]:
        s *= axis[2]
        return [[c, -s, 0.0, x], [s, c, 0.0, y], [0.0, 0.0, 1.0, z], [0.0, 0.0, 0.0, 1.0]]
    if axis[1]:
        s *= axis[1]
        return [[c, 0.0, s, x], [0.0, 1.0, 0.0, y], [-s, 0.0, c, z], [0.0, 0.0, 0.0, 1.0]]
    raise ValueError(f"joint axis {tuple(axis)}: only +-y and +-z are used by the LWR4+")


def link_rows(q_rad: Sequence[float] | F64, base: F64 | None = None) -> list[list[list[float]]]:
    """:func:`link_transforms` as rows of floats (``[t.tolist() for t in ...]``, the same
    values): what ``/tf`` needs, at a fraction of the cost of seven 4x4 arrays."""
    if len(q_rad) < JOINTS:
        raise ValueError(f"{len(q_rad)} joint positions; the LWR4+ has {JOINTS}")
    q = [float(v) for v in q_rad[:JOINTS]]
    out = [_joint_rows(_ORIGINS[i], _AXES[i], q[i]) for i in range(JOINTS)]
    if base is not None:
        first: list[list[float]] = (base @ np.array(out[0])).tolist()
        out[0] = first
    return out


def chain(transforms: Sequence[F64]) -> list[F64]:
    """Each frame of a chain of parent-relative transforms in the chain's root."""
    out: list[F64] = []
    pose = np.eye(4)
    for t in transforms:
        pose = pose @ t
        out.append(pose)
    return out


def flange_to_tcp(scene: Scene) -> F64:
    """The TCF in the flange (``link7``) frame: along z to the tool tip, turned 180 deg."""
    out = translation(0.0, 0.0, scene.tool.sensor_height + tool_tip_offset(scene))
    out[:2, :2] = -np.eye(2)
    return out


def base_pose(scene: Scene) -> F64:
    """The arm's base in the frame of the robot's poses (the simulator's world:
    ``arm.base_pos``; zero for the real robot's own base frame)."""
    return translation(*scene.arm.base_pos)


def tcp_pose(scene: Scene, q_rad: Sequence[float] | F64) -> F64:
    """The TCF pose in the robot's frame for joint positions ``q_rad``."""
    return chain(link_transforms(q_rad, base_pose(scene)))[-1] @ flange_to_tcp(scene)
