"""Where a scene puts the bed and the target, from the arm's start TCF. Pure maths.

The simulator places its glass and target this way from the TCF its arm reaches
at the start pose (:class:`~drivers.world.world.SimWorld`); ``ffexp.scene3d`` does
the same from the first measured TCF, so both draw the same rig.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from drivers.description.funnel import seat_depth
from drivers.description.scene import Scene

__all__ = ["Layout", "compute_layout", "funnel_axis_height"]


@dataclass(frozen=True)
class Layout:
    """Where the scene puts things (world frame), derived from the start TCF."""

    glass_z: float
    target_pos: NDArray[np.float64]
    target_yaw: float
    """The target's turn about the vertical [rad] (the air bed's hinge angle)."""
    target_rot: NDArray[np.float64]
    """The target's orientation, 3x3 in the world frame (yaw, then the free target's
    pitch about its own y and roll about its own x)."""
    funnel_in_target: NDArray[np.float64]
    """Mouth centre of the target funnel in the target body frame."""
    funnel_seat_depth: float
    """Insertion depth of the tool tip when the cones are seated [m]."""
    objects: dict[str, NDArray[np.float64]]
    """Where each of the scene's ``objects`` starts: its centre in the world [m]."""


def funnel_axis_height(scene: Scene) -> float:
    """Height of the target funnel's axis above the glass [m]."""
    f = scene.target.funnel
    return scene.target.size[2] + f.opening + f.capsule_radius + 0.005


def _turn(axis: int, angle: float) -> NDArray[np.float64]:
    """The rotation by ``angle`` [rad] about coordinate axis ``axis`` (0 x, 1 y, 2 z)."""
    c, s = math.cos(angle), math.sin(angle)
    i, j = (axis + 1) % 3, (axis + 2) % 3
    out = np.eye(3)
    out[i, i] = out[j, j] = c
    out[j, i], out[i, j] = s, -s
    return out


def compute_layout(
    scene: Scene, tcp_pos: NDArray[np.float64], tcp_rot: NDArray[np.float64]
) -> Layout:
    """Place glass and target from the start TCF (``tcp_rot`` columns = TCF axes in world)."""
    tg = scene.target
    z_axis = tcp_rot[:, 2].copy()
    y_axis = tcp_rot[:, 1].copy()
    z_axis[2] = 0.0
    y_axis[2] = 0.0
    z_axis /= max(float(np.linalg.norm(z_axis)), 1e-12)
    y_axis /= max(float(np.linalg.norm(y_axis)), 1e-12)
    h = funnel_axis_height(scene)
    glass_z = float(tcp_pos[2]) - h
    mouth = tcp_pos + tg.distance * z_axis + tg.lateral * y_axis
    mouth[2] = tcp_pos[2] + tg.vertical
    yaw0 = math.atan2(z_axis[1], z_axis[0])
    yaw = yaw0 + math.radians(tg.yaw_deg)
    funnel_in_target = np.array(
        [-tg.size[0] / 2.0, 0.0, h - tg.size[2] / 2.0], dtype=np.float64
    )
    c, s = math.cos(yaw), math.sin(yaw)
    rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    if tg.pitch_deg or tg.roll_deg:
        rot = rz @ _turn(1, math.radians(tg.pitch_deg)) @ _turn(0, math.radians(tg.roll_deg))
    else:
        rot = rz
    center = mouth - rot @ funnel_in_target
    return Layout(
        glass_z=glass_z,
        target_pos=center,
        target_yaw=yaw,
        target_rot=rot,
        funnel_in_target=funnel_in_target,
        funnel_seat_depth=seat_depth(scene),
        objects={o.name: tcp_pos + o.distance * z_axis + o.lateral * y_axis
                 + np.array([0.0, 0.0, o.vertical]) for o in scene.objects},
    )
