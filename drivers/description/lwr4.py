"""The KUKA LWR4+: its published kinematics, limits, link inertias and drive numbers.

Written by us from published numbers; no third-party model file is copied.

* Kinematics (joint offsets 0.11 / 0.2005 / 0.20 / 0.20 / 0.20 / 0.19 /
  0.078 m along the parent's z, axes +z -y +z +y +z -y +z, position limits
  170/120 deg, velocity limits): CentroEPiaggio/kuka-lwr
  ``lwr_description/model/kuka_lwr.urdf.xacro`` (commit 464d48c); the position
  limits also in the KRC's ``rsidef7.dat`` via TUM kuka_fri.
* Link masses, centres of mass and principal inertias: the AUTh mesh-derived
  set, iSaran/robamine ``rlrl-py/rlrl_py/envs/assets/xml/lwr/lwr_robot.xml``
  ("Source: auth-arl/autharl_core"). The principal-axis orientations of that
  file are not in our fact sheet, so the principal moments are used about the
  link axes (an approximation of second order: the off-diagonal terms).
* Joint friction and reflected rotor inertia: Jubien 2014 identified values
  (ISIR-SYROCO/kukaKDL ``kukakdl_const.hpp``; fact sheet section 1(d)). They
  are drive-side; the LWR's torque loop hides most of them, so a scene scales
  them (``arm.friction_scale``, ``arm.armature_scale``).
"""

from __future__ import annotations

from drivers.description.arm import ArmDescription

__all__ = ["FLOBAROID_LINK_COULOMB", "FLOBAROID_LINK_VISCOUS", "JUBIEN_COULOMB", "JUBIEN_ROTOR",
           "JUBIEN_VISCOUS", "LWR4"]

#: Jubien 2014 identified drive-side joint friction of the LWR4+ (fact sheet
#: section 1(d), ISIR-SYROCO/kukaKDL kukakdl_const.hpp): Coulomb [N m].
JUBIEN_COULOMB = (11.9, 11.5, 8.98, 8.35, 8.31, 4.72, 6.04)
#: ... and viscous [N m s/rad], same source.
JUBIEN_VISCOUS = (14.4, 15.3, 6.55, 11.0, 4.29, 2.26, 1.6)
#: Jubien 2014 reflected rotor inertias [kg m^2] for A3..A7; A1/A2 are not
#: separable from the grouped parameters and are taken equal to A3 (assumption).
JUBIEN_ROTOR = (2.01, 2.01, 2.01, 1.92, 0.776, 0.391, 0.399)
#: Joint friction after the torque sensors (link side) of an LWR4+: the joint-torque-sensor
#: residual after SDP inertial identification in kjyv/FloBaRoID documentation/TUTORIAL
#: (its provenance is uncertain: an older version called the example simulated):
#: Coulomb [N m] ...
FLOBAROID_LINK_COULOMB = (0.611, 0.363, 0.304, 0.473, 0.595, 0.160, 0.038)
#: ... and viscous [N m s/rad], same source.
FLOBAROID_LINK_VISCOUS = (1.069, 0.958, 0.223, 0.689, 0.065, 0.252, 0.076)

#: The LWR4+ (sources: the module's docstring).
LWR4 = ArmDescription(
    name="KUKA LWR4+",
    # joint-origin offsets along the parent z axis [m] (CentroEPiaggio URDF)
    joint_origins_m=tuple((0.0, 0.0, z) for z in (0.11, 0.2005, 0.20, 0.20, 0.20, 0.19, 0.078)),
    # joint axes in the link frame (CentroEPiaggio URDF)
    joint_axes=((0, 0, 1), (0, -1, 0), (0, 0, 1), (0, 1, 0), (0, 0, 1), (0, -1, 0), (0, 0, 1)),
    # CentroEPiaggio URDF; also KRC rsidef7.dat via TUM kuka_fri
    position_limits_deg=(170.0, 120.0, 170.0, 120.0, 170.0, 120.0, 170.0),
    # CentroEPiaggio URDF
    velocity_limits_degps=(110.0, 110.0, 128.0, 128.0, 204.0, 184.0, 184.0),
    # links 1..7, AUTh mesh-derived set
    link_masses_kg=(2.59818, 2.61292, 2.59818, 2.61292, 1.94073, 1.27744, 0.0698888),
    link_coms_m=(
        (0.0, 0.0387, 0.1519),
        (0.0, -0.0371, 0.0615),
        (0.0, -0.0387, 0.1519),
        (0.0, 0.0371, 0.0615),
        (0.0004, 0.0296, 0.1109),
        (0.0, -0.0140, -0.0012),
        (0.0, 0.0, -0.0087),
    ),
    link_inertias_kgm2=(
        (0.01432, 0.01406, 0.00483),
        (0.01675, 0.01618, 0.00449),
        (0.01432, 0.01406, 0.00483),
        (0.01675, 0.01618, 0.00449),
        (0.00995, 0.00893, 0.00301),
        (0.00286, 0.00247, 0.00232),
        (4.7e-5, 2.5e-5, 2.5e-5),
    ),
    rotor_inertias_kgm2=JUBIEN_ROTOR,
    drive_coulomb_nm=JUBIEN_COULOMB,
    drive_viscous_nmsprad=JUBIEN_VISCOUS,
    link_coulomb_nm=FLOBAROID_LINK_COULOMB,
    link_viscous_nmsprad=FLOBAROID_LINK_VISCOUS,
)
