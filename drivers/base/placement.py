"""The tool tip's placement in the target funnel: one definition for truth and trackers.

Pure maths, no I/O. The funnel mouth frame has its origin at the centre of
the funnel's mouth and its x axis along the funnel axis, into the target;
the tool's approach axis is its TCP frame's z. Both poses are 4x4 in the same
frame (the robot base frame, or the simulator's world, whose z is up).
"""

from __future__ import annotations

import math

from drivers.base.types import F64

__all__ = ["Placement", "placement", "placement_at_mouth", "wrap_angle"]


def wrap_angle(a: float) -> float:
    """``a`` wrapped to [-pi, pi) [rad]."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


class Placement(tuple[float, float, float, float]):
    """``(insertion, lateral, vertical, yaw)``: the tool tip in the mouth frame [m]
    (depth past the mouth along the funnel axis, horizontal and vertical offsets
    from the axis) and the tool axis' heading minus the funnel axis' [rad]."""

    __slots__ = ()

    @property
    def insertion(self) -> float:
        return self[0]

    @property
    def lateral(self) -> float:
        return self[1]

    @property
    def vertical(self) -> float:
        return self[2]

    @property
    def yaw(self) -> float:
        return self[3]


def placement(tcp_pose: F64, mouth_pose: F64) -> Placement:
    """Where the tool tip (``tcp_pose``) is in the funnel whose mouth frame is ``mouth_pose``.

    The yaw compares headings in the horizontal plane: the tool's z axis and
    the funnel's x axis, each projected on the base frame's x-y plane.
    """
    d = (tcp_pose[:3, 3] - mouth_pose[:3, 3]) @ mouth_pose[:3, :3]
    x, y, z = d.tolist()
    yaw = wrap_angle(math.atan2(tcp_pose[1, 2], tcp_pose[0, 2])
                     - math.atan2(mouth_pose[1, 0], mouth_pose[0, 0]))
    return Placement((x, y, z, yaw))


def placement_at_mouth(tcp_pose: F64, mouth_pos: F64, mouth_mat9: F64) -> Placement:
    """:func:`placement` with the mouth frame given as a position and a row-major 3x3
    rotation (MuJoCo's ``xpos``/``xmat``): the same values, no 4x4 built."""
    d = (tcp_pose[:3, 3] - mouth_pos) @ mouth_mat9.reshape(3, 3)
    x, y, z = d.tolist()
    yaw = wrap_angle(math.atan2(tcp_pose[1, 2], tcp_pose[0, 2])
                     - math.atan2(mouth_mat9[3], mouth_mat9[0]))
    return Placement((x, y, z, yaw))
