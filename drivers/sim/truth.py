"""What only the simulator knows about a cycle: the target's pose and motion, the tool's
placement in the funnel and the simulator's own seating test. Pure, no I/O."""

from __future__ import annotations

import math

import numpy as np

from drivers.base.placement import placement_at_mouth
from drivers.base.types import F64, GroundTruth

__all__ = ["SEAT_DEPTH_TOL", "SEAT_LATERAL_TOL", "SEAT_YAW_TOL", "ground_truth", "pose"]

#: Seated: tool tip within this of the (estimated) seat depth [m] ...
SEAT_DEPTH_TOL = 0.005
#: ... and this close to the funnel axis [m] ...
SEAT_LATERAL_TOL = 0.0025
#: ... and axes within this yaw [rad]. Lateral and yaw tolerances were set from
#: the play of the earlier capsule funnels (about 1-2 mm, 2-3 deg); they are
#: unchanged for the smooth funnels.
SEAT_YAW_TOL = math.radians(3.0)

_EYE4 = np.eye(4)


def pose(pos: F64, mat9: F64) -> F64:
    """4x4 pose from a position and a row-major 3x3 rotation (MuJoCo's ``xmat``)."""
    out = _EYE4.copy()
    out[:3, :3] = mat9.reshape(3, 3)
    out[:3, 3] = pos
    return out


def ground_truth(
    target_pose: F64,
    target_twist: F64,
    tcp_pose: F64,
    mouth_pos: F64,
    mouth_mat9: F64,
    seat_depth_m: float,
    contact: F64,
    touching: bool,
    tcp_twist: F64,
) -> GroundTruth:
    """The tool tip in the funnel-mouth frame (x along the funnel axis), its yaw
    against the funnel's, and whether the simulator calls it seated."""
    insertion, lateral, vertical, yaw_err = placement_at_mouth(tcp_pose, mouth_pos, mouth_mat9)
    seated = (
        insertion >= seat_depth_m - SEAT_DEPTH_TOL
        and abs(lateral) <= SEAT_LATERAL_TOL
        and abs(yaw_err) <= SEAT_YAW_TOL
    )
    return GroundTruth(
        target_pose=target_pose,
        target_twist=target_twist,
        contact_wrench=contact,
        lateral_error=lateral,
        vertical_error=vertical,
        yaw_error=yaw_err,
        insertion=insertion,
        seated=seated,
        in_contact=touching,
        tcp_twist=tcp_twist,
    )
