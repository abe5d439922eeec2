"""A simulator truth whose funnel placement is given: the tool's TCP and the funnel mouth
as the truth's named frames, placed so that :func:`ffexp.scenarios.funnel.truth_placement`
reads back ``(insertion, lateral, vertical, yaw)``."""

from __future__ import annotations

import math

import numpy as np

from drivers.base.types import GroundTruth

#: The paper pose's TCF: X up, Y along world -y, Z (the approach) along world +x.
TCP_ROT = np.array([[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]])


def funnel_truth(insertion_m: float = 0.0, lateral_m: float = 0.0, vertical_m: float = 0.0,
                 yaw_rad: float = 0.0, in_contact: bool = False) -> GroundTruth:
    tcp = np.eye(4)
    tcp[:3, :3] = TCP_ROT
    tcp[:3, 3] = (0.65, 0.0, 0.5)
    c, s = math.cos(-yaw_rad), math.sin(-yaw_rad)
    mouth = np.eye(4)
    mouth[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    mouth[:3, 3] = tcp[:3, 3] - mouth[:3, :3] @ np.array([insertion_m, lateral_m, vertical_m])
    return GroundTruth(sites={"tcp": tcp, "funnel_mouth": mouth}, in_contact=in_contact)
