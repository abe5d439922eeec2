"""The UR5e's published kinematic and dynamic parameters, and its forward kinematics (pure).

Source: Universal Robots, "DH Parameters for calculations of kinematics and
dynamics" (support article, UR3e/UR5e/UR10e/UR16e tables; UR's "a" is the
standard DH "r"). UR notes there that the link inertia matrices of the UR3e
and UR5e are negligible and does not publish them; a model built from these
numbers must choose its own (and say so). Limits: UR5e technical
specifications (working range +-360 deg on every joint, joint speed 180 deg/s,
tool speed 1 m/s, payload 5 kg, reach 850 mm).

These numbers belong with the robot's description; they live here until the
neutral description package takes them.
"""

from __future__ import annotations

import math
from typing import Final

import numpy as np
from numpy.typing import NDArray

#: Standard DH parameters per joint 1..6 (theta offsets are all 0).
DH_A_M: Final = (0.0, -0.425, -0.3922, 0.0, 0.0, 0.0)
DH_D_M: Final = (0.1625, 0.0, 0.0, 0.1333, 0.0997, 0.0996)
DH_ALPHA_RAD: Final = (math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0)

#: Link masses [kg], links 1..6.
LINK_MASS_KG: Final = (3.761, 8.058, 2.846, 1.37, 1.3, 0.365)
#: Centres of mass [m], each in its link's DH frame.
LINK_COM_M: Final = (
    (0.0, -0.02561, 0.00193),
    (0.2125, 0.0, 0.11336),
    (0.15, 0.0, 0.0265),
    (0.0, -0.0018, 0.01634),
    (0.0, 0.0018, 0.01634),
    (0.0, 0.0, -0.001159),
)

#: Joint range [rad] (+-360 deg) and speed limit [rad/s] (180 deg/s), every joint.
JOINT_LIMIT_RAD: Final = 2 * math.pi
JOINT_SPEED_LIMIT_RADPS: Final = math.pi
#: Tool speed limit [m/s], rated payload [kg], reach [m].
TOOL_SPEED_LIMIT_MPS: Final = 1.0
PAYLOAD_KG: Final = 5.0
REACH_M: Final = 0.85


def dh_transform(theta: float, a: float, d: float, alpha: float) -> NDArray[np.float64]:
    """One standard DH link transform: Rot_z(theta) Trans_z(d) Trans_x(a) Rot_x(alpha)."""
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return np.array([[ct, -st * ca, st * sa, a * ct],
                     [st, ct * ca, -ct * sa, a * st],
                     [0.0, sa, ca, d],
                     [0.0, 0.0, 0.0, 1.0]])


def forward_kinematics(q_rad: NDArray[np.float64] | list[float]) -> NDArray[np.float64]:
    """The flange pose (4x4, base frame [m]) at joint positions ``q_rad``."""
    pose = np.eye(4)
    for theta, a, d, alpha in zip(q_rad, DH_A_M, DH_D_M, DH_ALPHA_RAD, strict=True):
        pose = pose @ dh_transform(float(theta), a, d, alpha)
    return pose
