"""Forward kinematics of the scene's arm with the rig's sensor and tool. Pure, no I/O.

The chain is the published one the simulator is built from, the scene's
``arm.description`` (an :class:`~drivers.description.arm.ArmDescription`: the
LWR4+ by default, :data:`~drivers.description.lwr4.LWR4`, or the UR5e): frame
``link{i}`` sits at ``joint_origins_m[i-1]`` of its parent (``link{i-1}``, the
base for ``link1``), turned by ``joint_rpy_rad[i-1]`` (a DH arm's fixed turns;
the LWR4+ has none), and turns by joint ``i`` about its axis. The flange is
``flange_m`` (turned by ``flange_rpy_rad``) in the last link, the LWR4+'s at
``link7``'s origin; the F/T sensor and the tool follow along its z axis, and
the TCF (the tool tip) is the flange frame moved ``sensor_height +
shaft_length + funnel.depth`` along z and turned by 180 deg about it (as the
simulator's model, :mod:`drivers.world.mjcf`).

For a chain without fixed turns whose axes are +-y and +-z (the LWR4+) the
rotations are written out: a 4x4 from ``cos`` and ``sin`` costs a few
microseconds where ``scipy``'s ``Rotation`` costs tens. Other chains take the
description's own :meth:`~drivers.description.arm.ArmDescription.joint_transforms`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from drivers.base.types import F64
from drivers.config import Vec3
from drivers.description import LWR4, Scene, tool_tip_offset
from drivers.description.arm import ArmDescription, rpy_matrix

__all__ = ["flange_in_last_link", "flange_to_tcp", "link_frames", "link_rows",
           "link_transforms", "translation"]


def translation(x: float, y: float, z: float) -> F64:
    """A 4x4 translation."""
    out = np.eye(4)
    out[:3, 3] = (x, y, z)
    return out


def link_frames(arm: ArmDescription = LWR4) -> tuple[str, ...]:
    """``/tf`` frames of the arm's links: ``link1`` .. ``link{joints}``."""
    return tuple(f"link{i + 1}" for i in range(arm.joints))


def _written_out(arm: ArmDescription) -> bool:
    """Whether the chain's rotations are the written-out ones (module docstring)."""
    return arm.joint_rpy_rad is None and all(not a[0] for a in arm.joint_axes)


def _angles(q_rad: Sequence[float] | F64, arm: ArmDescription) -> list[float]:
    if len(q_rad) < arm.joints:
        raise ValueError(f"{len(q_rad)} joint positions; the {arm.name} has {arm.joints}")
    if type(q_rad) is np.ndarray and q_rad.dtype == np.float64 and q_rad.ndim == 1:
        out: list[float] = q_rad[:arm.joints].tolist()  # the same floats, at once
        return out
    return [float(v) for v in q_rad[:arm.joints]]


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
        raise ValueError(f"joint axis {tuple(axis)}: only +-y and +-z are written out")
    return out


def link_transforms(q_rad: Sequence[float] | F64, base: F64 | None = None,
                    arm: ArmDescription = LWR4) -> list[F64]:
    """Pose of every ``link{i}`` of ``arm`` in its parent (``base``'s frame for
    ``link1``, which includes ``base``, the arm's base in the robot's frame)."""
    q = _angles(q_rad, arm)
    if _written_out(arm):
        out = [_joint(arm.joint_origins_m[i], arm.joint_axes[i], q[i])
               for i in range(arm.joints)]
    else:
        out = arm.joint_transforms(q)
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
    raise ValueError(f"joint axis {tuple(axis)}: only +-y and +-z are written out")


def link_rows(q_rad: Sequence[float] | F64, base: F64 | None = None,
              arm: ArmDescription = LWR4) -> list[list[list[float]]]:
    """:func:`link_transforms` as rows of floats (``[t.tolist() for t in ...]``, the same
    values): what ``/tf`` needs, written out at a fraction of the cost of 4x4 arrays."""
    if not _written_out(arm):
        return [t.tolist() for t in link_transforms(q_rad, base, arm)]
    q = _angles(q_rad, arm)
    out = [_joint_rows(arm.joint_origins_m[i], arm.joint_axes[i], q[i])
           for i in range(arm.joints)]
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


def flange_in_last_link(arm: ArmDescription) -> F64 | None:
    """The flange in the arm's last link frame (``None``: at its origin, unturned)."""
    if not any(arm.flange_m) and not any(arm.flange_rpy_rad):
        return None
    out = translation(*arm.flange_m)
    out[:3, :3] = rpy_matrix(arm.flange_rpy_rad)
    return out


def flange_to_tcp(scene: Scene) -> F64:
    """The TCF in the flange frame: along z to the tool tip, turned 180 deg."""
    out = translation(0.0, 0.0, scene.tool.sensor_height + tool_tip_offset(scene))
    out[:2, :2] = -np.eye(2)
    return out


def base_pose(scene: Scene) -> F64:
    """The arm's base in the frame of the robot's poses (the simulator's world:
    ``arm.base_pos``; zero for the real robot's own base frame)."""
    return translation(*scene.arm.base_pos)


def tcp_pose(scene: Scene, q_rad: Sequence[float] | F64) -> F64:
    """The TCF pose in the robot's frame for joint positions ``q_rad``."""
    arm = scene.arm.description
    last = chain(link_transforms(q_rad, base_pose(scene), arm))[-1]
    flange = flange_in_last_link(arm)
    return (last if flange is None else last @ flange) @ flange_to_tcp(scene)
