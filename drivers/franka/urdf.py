"""The FR3's URDF as the robot hands it to libfranka (``GetRobotModel``), written from its
description (:data:`drivers.description.fr3.FR3`). Pure: text only.

libfranka (>= 0.15) builds its dynamic model from the URDF the robot sends and looks the
flange up by the link name ``link8``, so the links are ``link0`` .. ``link8`` and the
joints ``joint1`` .. ``joint7`` (``joint8`` fixed: the flange). libfranka 0.21 also wants
each joint's ``position_based_velocity_limits`` (its rate limiter's speed bound near a
position limit); the FR3's are not among the published numbers we use, so every joint
gets :data:`DECELERATION_LIMIT_RADPS2` and no offset (our choice: libfranka reads them only
to limit motion-generator rates, which a torque loop does not use).
"""

from __future__ import annotations

import math

from drivers.description.arm import ArmDescription
from drivers.description.fr3 import FR3, TORQUE_LIMITS_NM

__all__ = ["DECELERATION_LIMIT_RADPS2", "urdf"]

#: The deceleration a joint's speed bound near its limit assumes [rad/s^2] (our choice).
DECELERATION_LIMIT_RADPS2 = 10.0


def _v(values: tuple[float, ...] | list[float]) -> str:
    return " ".join(f"{float(x):.9g}" for x in values)


def urdf(arm: ArmDescription = FR3, torque_limits_nm: tuple[float, ...] = TORQUE_LIMITS_NM
         ) -> str:
    """The arm's kinematic chain, limits and link inertias as a URDF document."""
    rpy = arm.joint_rpy_rad or ((0.0, 0.0, 0.0),) * arm.joints
    lower = arm.lower_limits_deg
    parts = ['<?xml version="1.0"?>', '<robot name="fr3">', '  <link name="link0"/>']
    for i in range(arm.joints):
        ixx, iyy, izz = arm.link_inertias_kgm2[i]
        parts += [
            f'  <link name="link{i + 1}">',
            f'    <inertial><origin xyz="{_v(arm.link_coms_m[i])}" rpy="0 0 0"/>'
            f'<mass value="{arm.link_masses_kg[i]:.9g}"/>'
            f'<inertia ixx="{ixx:.9g}" ixy="0" ixz="0" iyy="{iyy:.9g}" iyz="0" izz="{izz:.9g}"/>'
            f'</inertial>',
            '  </link>',
            f'  <joint name="joint{i + 1}" type="revolute">',
            f'    <parent link="link{i}"/><child link="link{i + 1}"/>',
            f'    <origin xyz="{_v(arm.joint_origins_m[i])}" rpy="{_v(rpy[i])}"/>',
            f'    <axis xyz="{_v(arm.joint_axes[i])}"/>',
            f'    <limit lower="{math.radians(lower[i]):.9g}" '
            f'upper="{math.radians(arm.position_limits_deg[i]):.9g}" '
            f'effort="{torque_limits_nm[i]:.9g}" '
            f'velocity="{math.radians(arm.velocity_limits_degps[i]):.9g}"/>',
            f'    <position_based_velocity_limits deceleration_limit='
            f'"{DECELERATION_LIMIT_RADPS2:.9g}" velocity_offset="0"/>',
            '  </joint>',
        ]
    parts += [
        '  <link name="link8"/>',
        '  <joint name="joint8" type="fixed">',
        f'    <parent link="link{arm.joints}"/><child link="link8"/>',
        f'    <origin xyz="{_v(arm.flange_m)}" rpy="{_v(arm.flange_rpy_rad)}"/>',
        '  </joint>',
        '</robot>',
    ]
    return "\n".join(parts) + "\n"
