"""The Franka Research 3 (FR3): its published kinematics, limits, masses and drive inertias.

Written by us from published numbers; no model file is copied.

* Kinematics: Franka's "Robot and interface specifications" (FCI documentation,
  Denavit-Hartenberg parameters in Craig's modified convention, the same table for
  the FR3 and the Panda): per joint ``a``, ``d``, ``alpha`` with
  ``Rx(alpha_i) Tx(a_i) Rz(theta_i) Tz(d_i)``, the flange 0.107 m along the last
  joint's z.
* Limits: the same documentation's FR3 table: joint position ranges (joints 4 and
  6 are not symmetric), joint speeds 2.62 rad/s (joints 1-4), 5.26, 4.18, 5.26 rad/s
  (joints 5-7), joint torques 87 N m (1-4) and 12 N m (5-7), torque rate 1000 N m/s.
* Link masses, centres of mass and inertias: Franka publishes the FR3's in its ROS
  description, which we could not read here; these are the identified values of the
  Franka arm's links (Ledezma and Haddadin, "FOP Networks for Learning Humanoid Body
  Schema and Dynamics", 2021, Fig. 4, as tabulated by the Explicit-robotics project's
  "Derivation of franka's inertia parameters": mass, mass times centre of mass and the
  inertia about the centre of mass, each in its joint's DH frame). Only the
  principal moments about the link axes are used (as for the other arms).
* Reflected drive inertias: Franka's values for the FR3, as quoted by Drake's
  ``franka_description`` README (0.6057, 0.6057, 0.4625, 0.4625, 0.2055 x 3 kg m^2).
* Joint friction: not published; the scene gives it (``data/scenes/paper-fr3.toml``).
"""

from __future__ import annotations

import math
from typing import Final

from drivers.config import Vec3
from drivers.description.arm import ArmDescription

__all__ = ["DH_ALPHA_RAD", "DH_A_M", "DH_D_M", "FLANGE_D_M", "FR3", "LINK_MASS_KG",
           "PAPER_SCENE_OVERRIDES", "POSITION_LOWER_RAD", "POSITION_UPPER_RAD",
           "TORQUE_LIMITS_NM", "TORQUE_RATE_LIMIT_NMPS", "VELOCITY_LIMITS_RADPS"]

#: Modified DH parameters per joint 1..7 (Franka's table).
DH_A_M: Final = (0.0, 0.0, 0.0, 0.0825, -0.0825, 0.0, 0.088)
DH_D_M: Final = (0.333, 0.0, 0.316, 0.0, 0.384, 0.0, 0.0)
DH_ALPHA_RAD: Final = (0.0, -math.pi / 2, math.pi / 2, math.pi / 2, -math.pi / 2,
                       math.pi / 2, math.pi / 2)
#: The flange along the last joint's z [m].
FLANGE_D_M: Final = 0.107
#: Joint position limits [rad] (FR3).
POSITION_LOWER_RAD: Final = (-2.7437, -1.7837, -2.9007, -3.0421, -2.8065, 0.5445, -3.0159)
POSITION_UPPER_RAD: Final = (2.7437, 1.7837, 2.9007, -0.1518, 2.8065, 4.5169, 3.0159)
#: Joint speed limits [rad/s] (FR3).
VELOCITY_LIMITS_RADPS: Final = (2.62, 2.62, 2.62, 2.62, 5.26, 4.18, 5.26)
#: Joint torque limits [N m] and torque rate limit [N m/s] (FR3).
TORQUE_LIMITS_NM: Final = (87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0)
TORQUE_RATE_LIMIT_NMPS: Final = 1000.0
#: Link masses [kg], links 1..7 (module docstring).
LINK_MASS_KG: Final = (4.9707, 0.6469, 3.2286, 3.5879, 1.2259, 1.6666, 1.4655)
#: Mass times centre of mass [kg m], each in its joint's DH frame.
_MASS_COM: Final = (
    (0.0193, 0.0103, -0.4654),
    (-0.0020, -0.0186, 0.0023),
    (0.0888, 0.1267, -0.2147),
    (-0.1908, 0.3746, 0.0985),
    (-0.0147, 0.0503, -0.0471),
    (0.1002, -0.0235, -0.0175),
    (0.0004, -0.0031, 0.1453),
)
#: Principal moments about the link axes at the centre of mass [kg m^2] (Ixx, Iyy, Izz).
_INERTIA: Final = (
    (0.7470, 0.7503, 0.0092),
    (0.0085, 0.0281, 0.0265),
    (0.0565, 0.0529, 0.0182),
    (0.0677, 0.0324, 0.0776),
    (0.0394, 0.0315, 0.0109),
    (0.0025, 0.0106, 0.0118),
    (0.0308, 0.0284, 0.0067),
)
#: Reflected drive inertias [kg m^2] (module docstring).
ROTOR_INERTIA_KGM2: Final = (0.605721456, 0.605721456, 0.462474144, 0.462474144,
                             0.205544064, 0.205544064, 0.205544064)


def _origin(i: int) -> Vec3:
    """Joint ``i``'s frame in its parent: ``Rx(alpha) Tx(a) Tz(d)`` applied to the origin."""
    a, d, al = DH_A_M[i], DH_D_M[i], DH_ALPHA_RAD[i]
    return (a, -d * math.sin(al), d * math.cos(al))


def _com(i: int) -> Vec3:
    m = LINK_MASS_KG[i]
    x, y, z = _MASS_COM[i]
    return (x / m, y / m, z / m)


#: The FR3 (sources: the module's docstring).
FR3 = ArmDescription(
    name="Franka FR3",
    joint_origins_m=tuple(_origin(i) for i in range(7)),
    joint_axes=((0, 0, 1),) * 7,
    position_limits_deg=tuple(math.degrees(v) for v in POSITION_UPPER_RAD),
    position_lower_deg=tuple(math.degrees(v) for v in POSITION_LOWER_RAD),
    velocity_limits_degps=tuple(math.degrees(v) for v in VELOCITY_LIMITS_RADPS),
    link_masses_kg=LINK_MASS_KG,
    link_coms_m=tuple(_com(i) for i in range(7)),
    link_inertias_kgm2=_INERTIA,
    joint_rpy_rad=tuple((al, 0.0, 0.0) for al in DH_ALPHA_RAD),
    flange_m=(0.0, 0.0, FLANGE_D_M),
    rotor_inertias_kgm2=ROTOR_INERTIA_KGM2,
)

#: The scene fields that turn the paper's scene into ``data/scenes/paper-fr3.toml``
#: (``dotted.key=value`` overrides): the FR3 on a pedestal 0.2331 m below the LWR4+'s
#: base, its start pose putting its TCP where the LWR4+'s is, (0.65, 0, 0.50) m with TCF
#: X up and Z along world +x (to 0.1 mm and 0.1 mrad: solved once by least squares,
#: the joints rounded to 0.1 mrad), the FCI's 1 kHz torque cycle as the world's step, its
#: torque limits, and our assumed joint friction (not published: of the order of the
#: LWR4+'s link-side residual in data/scenes/paper.toml).
PAPER_SCENE_OVERRIDES: Final = (
    "name='paper-fr3'",
    "fri.cycle=0.001",
    "arm.model='fr3'",
    "arm.base_pos=[0.0, 0.0, -0.2331]",
    "arm.q_init=[0.0967, -0.0187, 0.0939, -1.5915, 1.5617, 3.3322, 1.5819]",
    "arm.coulomb=[0.008, 0.008, 0.008, 0.008, 0.003, 0.003, 0.003]",
    "arm.viscous=[0.01, 0.01, 0.01, 0.01, 0.002, 0.002, 0.002]",
    f"arm.torque_limits={list(TORQUE_LIMITS_NM)}",
)
