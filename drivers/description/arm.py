"""An arm's description: its kinematic chain, joint limits and link inertias. Pure data.

One :class:`ArmDescription` per arm model (:data:`drivers.description.lwr4.LWR4`); the
simulator builds its model from it, the emulated controller takes its limits from it and
``ffexp.scene3d`` draws the arm by its forward kinematics.

The chain: frame ``link{i}`` sits at ``joint_origins_m[i-1]`` in its parent (``link{i-1}``,
the arm's base for ``link1``), with the parent's axes at zero joint angle, and turns by joint
``i`` about ``joint_axes[i-1]`` (a unit axis of the link frame). The flange is the last link's
origin.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["ArmDescription", "Vec3"]

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class ArmDescription:
    """One arm model's published numbers, per joint or link ``1..n`` in order.

    Attributes:
        name: the model's name (``"KUKA LWR4+"``).
        joint_origins_m: each joint's frame origin in its parent link's frame [m].
        joint_axes: each joint's axis in its own link frame (``+-x``, ``+-y``, ``+-z``).
        position_limits_deg: symmetric joint position limits [deg].
        velocity_limits_degps: joint speed limits [deg/s].
        link_masses_kg: link masses [kg].
        link_coms_m: link centres of mass in the link frame [m].
        link_inertias_kgm2: principal moments of inertia about the link axes [kg m^2].
        rotor_inertias_kgm2: each drive's reflected rotor inertia [kg m^2].
        drive_coulomb_nm: each drive's identified Coulomb friction [N m].
        drive_viscous_nmsprad: each drive's identified viscous friction [N m s/rad].
    """

    name: str
    joint_origins_m: tuple[Vec3, ...]
    joint_axes: tuple[tuple[int, int, int], ...]
    position_limits_deg: tuple[float, ...]
    velocity_limits_degps: tuple[float, ...]
    link_masses_kg: tuple[float, ...]
    link_coms_m: tuple[Vec3, ...]
    link_inertias_kgm2: tuple[Vec3, ...]
    rotor_inertias_kgm2: tuple[float, ...]
    drive_coulomb_nm: tuple[float, ...]
    drive_viscous_nmsprad: tuple[float, ...]

    def __post_init__(self) -> None:
        n = len(self.joint_origins_m)
        for name in ("joint_axes", "position_limits_deg", "velocity_limits_degps",
                     "link_masses_kg", "link_coms_m", "link_inertias_kgm2",
                     "rotor_inertias_kgm2", "drive_coulomb_nm", "drive_viscous_nmsprad"):
            if len(getattr(self, name)) != n:
                raise ValueError(f"{self.name}: {name} has {len(getattr(self, name))} "
                                 f"entries for {n} joints")
        for axis in self.joint_axes:
            if sorted(abs(a) for a in axis) != [0, 0, 1]:
                raise ValueError(f"{self.name}: joint axis {axis} is not a unit axis of the link")

    @property
    def joints(self) -> int:
        """Number of joints."""
        return len(self.joint_origins_m)
