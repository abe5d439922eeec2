"""The Universal Robots UR5e: its published kinematics, masses, limits, and what is not published.

Written by us from published numbers; no third-party model file is copied.

* Standard DH parameters, link masses and centres of mass: Universal Robots,
  "DH Parameters for calculations of kinematics and dynamics" (support
  article, the UR5e table; UR's "a" is the standard DH "r"; every theta
  offset is 0; each centre of mass is given in its link's DH frame).
* Link inertias: UR says there that the UR3e's and UR5e's are negligible and
  publishes none. A simulator needs positive ones: each link here is a
  uniform solid cylinder of :data:`LINK_RADIUS_M` along its DH segment (its
  ``a`` or ``d``, the longer), principal moments about the link axes (our
  choice, stated in docs/ur.md).
* Joint ranges and speeds: UR5e technical specifications (working range
  +-360 deg on every joint, maximum speed 180 deg/s on every joint; tool
  speed 1 m/s, payload 5 kg, reach 850 mm).
* Joint torque limits: UR publishes no joint torques in its specifications;
  the e-Series ROS description (Universal_Robots_ROS2_Description,
  ``config/ur5e/joint_limits.yaml``, BSD-3) gives 150 N m for the base,
  shoulder and elbow (size-3 joints) and 28 N m for the wrists (size 1).
* Joint friction and reflected rotor inertia: not published by UR; none
  here (``None``). A scene gives its arm's friction explicitly
  (``data/scenes/paper-ur5e.toml``: an assumption, stated there).
"""

from __future__ import annotations

import math
from typing import Final

import numpy as np

from drivers.config import Vec3
from drivers.description.arm import ArmDescription, dh_chain, rpy_matrix

__all__ = ["DH_ALPHA_RAD", "DH_A_M", "DH_D_M", "DH_LINK_COM_M", "LINK_MASS_KG", "LINK_RADIUS_M",
           "PAPER_SCENE_OVERRIDES",
           "PAYLOAD_KG", "REACH_M", "TOOL_SPEED_LIMIT_MPS", "TORQUE_LIMITS_NM", "UR5E"]

#: Standard DH parameters per joint 1..6 (UR's table; theta offsets all 0).
DH_A_M: Final = (0.0, -0.425, -0.3922, 0.0, 0.0, 0.0)
DH_D_M: Final = (0.1625, 0.0, 0.0, 0.1333, 0.0997, 0.0996)
DH_ALPHA_RAD: Final = (math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0)
#: Link masses [kg], links 1..6 (UR's table).
LINK_MASS_KG: Final = (3.761, 8.058, 2.846, 1.37, 1.3, 0.365)
#: Centres of mass [m], each in its link's DH frame (UR's table).
DH_LINK_COM_M: Final = (
    (0.0, -0.02561, 0.00193),
    (0.2125, 0.0, 0.11336),
    (0.15, 0.0, 0.0265),
    (0.0, -0.0018, 0.01634),
    (0.0, 0.0018, 0.01634),
    (0.0, 0.0, -0.001159),
)
#: Radius of the uniform cylinder each link's inertia is taken from [m] (our choice: UR
#: publishes no inertias; about the e-Series size-3 joint's housing).
LINK_RADIUS_M: Final = 0.045
#: Joint torque limits [N m] (ROS description's joint_limits.yaml; module docstring).
TORQUE_LIMITS_NM: Final = (150.0, 150.0, 150.0, 28.0, 28.0, 28.0)
#: Tool speed limit [m/s], rated payload [kg], reach [m] (UR5e specifications).
TOOL_SPEED_LIMIT_MPS: Final = 1.0
PAYLOAD_KG: Final = 5.0
REACH_M: Final = 0.85

_CHAIN = dh_chain(DH_A_M, DH_D_M, DH_ALPHA_RAD)


def _dh_fixed(i: int) -> np.ndarray:
    """``Tz(d_i) Tx(a_i) Rx(alpha_i)``: DH frame ``i`` in our link frame ``i``."""
    t = np.eye(4)
    t[:3, :3] = rpy_matrix((DH_ALPHA_RAD[i], 0.0, 0.0))
    t[:3, 3] = (DH_A_M[i], 0.0, DH_D_M[i])
    return t


def _com(i: int) -> Vec3:
    p = _dh_fixed(i) @ np.array([*DH_LINK_COM_M[i], 1.0])
    return (float(p[0]), float(p[1]), float(p[2]))


def _inertia(i: int) -> Vec3:
    """A uniform cylinder along the link's longer DH segment (x for ``a``, z for ``d``)."""
    m, r = LINK_MASS_KG[i], LINK_RADIUS_M
    length = max(abs(DH_A_M[i]), abs(DH_D_M[i]))
    axial = m * r * r / 2.0
    across = m * (3.0 * r * r + length * length) / 12.0
    if abs(DH_A_M[i]) > abs(DH_D_M[i]):
        return (axial, across, across)
    return (across, across, axial)


#: The UR5e (sources: the module's docstring).
UR5E = ArmDescription(
    name="UR5e",
    joint_origins_m=_CHAIN.joint_origins_m,
    joint_axes=((0, 0, 1),) * 6,
    position_limits_deg=(360.0,) * 6,
    velocity_limits_degps=(180.0,) * 6,
    link_masses_kg=LINK_MASS_KG,
    link_coms_m=tuple(_com(i) for i in range(6)),
    link_inertias_kgm2=tuple(_inertia(i) for i in range(6)),
    joint_rpy_rad=_CHAIN.joint_rpy_rad,
    flange_m=_CHAIN.flange_m,
    flange_rpy_rad=_CHAIN.flange_rpy_rad,
)

#: The scene fields that turn the paper's scene into ``data/scenes/paper-ur5e.toml`` (as
#: ``dotted.key=value`` overrides): the UR5e on a base 0.1333 m (its d4) to the side so
#: that joint 1 starts at 0, elbow up, its TCP where the LWR4+'s is with the same TCF,
#: UR's 500 Hz cycle, its torque limits and our assumed joint friction (UR publishes
#: none: of the order of the LWR4+'s link-side residual in data/scenes/paper.toml).
PAPER_SCENE_OVERRIDES: Final = (
    "name='paper-ur5e'",
    "fri.cycle=0.002",
    "arm.model='ur5e'",
    "arm.base_pos=[0.0, 0.1333, 0.0]",
    "arm.q_init=[0.0, -1.8274, -1.7718, 0.4576, 1.5708, 1.5708]",
    "arm.coulomb=[0.008, 0.008, 0.008, 0.003, 0.003, 0.003]",
    "arm.viscous=[0.01, 0.01, 0.01, 0.002, 0.002, 0.002]",
    f"arm.torque_limits={list(TORQUE_LIMITS_NM)}",
)
