"""The Franka back-end's rig tables (pydantic only): ``[robot] type = "franka"`` (a real FR3
or Panda over libfranka), ``"franka-sim"`` (the simulated FR3 in-process) and ``[ft] type =
"franka-wrench"`` (the robot's external wrench estimate). Their errors name the rig's fields.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, ClassVar, Literal

from pydantic import Field

from drivers.base.backend import DeviceConfig
from drivers.config import Floats2, PosFloat

__all__ = ["FrankaSettings", "FrankaSimConfig", "FrankaWrenchFt"]


class FrankaSettings(DeviceConfig):
    """A Franka arm (FR3, or a Panda on a matching system) over libfranka's FCI."""

    type: Literal["franka"] = "franka"
    robot_ip: str = Field(description="the robot's address (IPv4 or host name)")
    realtime: Literal["enforce", "ignore"] = "enforce"
    """libfranka's RealtimeConfig: ``enforce`` needs a real-time kernel (a lab PC);
    ``ignore`` runs on any (an emulator, a simulator)."""
    setpoint_every: Annotated[int, Field(ge=1, le=100)] = 5
    """1 kHz torque cycles per ffexp cycle: the driver's impedance law runs every cycle,
    ffexp's loop sets its set-point every ``setpoint_every`` (5: 200 Hz, the paper's)."""
    stiffness_max_npm_nmprad: Floats2 = (3000.0, 300.0)
    """Largest translational and rotational stiffness the law applies (clipped above)."""
    hold_stiffness_npm_nmprad: Floats2 = (2000.0, 150.0)
    """The stiffness that holds the arm where it is before the first command."""
    nullspace_stiffness_nmprad: Annotated[float, Field(ge=0.0)] = 10.0
    """Joint stiffness towards the pose at connect in the Jacobian's null space (the
    redundant elbow) [N m/rad]."""
    nullspace_damping_nmsprad: Annotated[float, Field(ge=0.0)] = 1.0
    """Joint damping in the Jacobian's null space [N m s/rad]."""
    collision_torque_nm: Annotated[float, Field(gt=0.0)] = 100.0
    """libfranka's collision thresholds on every joint (``set_collision_behavior``):
    above it the robot stops with a reflex [N m]."""
    collision_force_n: Annotated[float, Field(gt=0.0)] = 100.0
    """The same for the Cartesian wrench (forces [N], torques [N m] alike)."""
    min_success_rate: Annotated[float, Field(ge=0.0, le=1.0)] = 0.9
    """Below this ``control_command_success_rate`` the link is reported unhealthy."""
    connect_timeout_s: PosFloat = 5.0
    """How long the robot may take to answer the connection."""


class FrankaSimConfig(FrankaSettings):
    """The simulated FR3 in-process (lockstep, no sockets): the same driver and impedance
    law as over libfranka, the FR3's torque interface on the simulator's world."""

    type: Literal["franka-sim"] = "franka-sim"  # type: ignore[assignment]
    #: it runs the world in-process and leaves the world's F/T samples to the sim sensor
    offers: ClassVar[frozenset[str]] = frozenset({"world", "world-ft"})
    robot_ip: str = "127.0.0.1"
    realtime: Literal["enforce", "ignore"] = "ignore"
    scene_file: Path | None = None
    """Scene TOML of an FR3 (relative to the rig file); default: the protocol's scene with
    the FR3 in the LWR4+'s place (data/scenes/paper-fr3.toml)."""
    truth: bool = True
    """Attach the simulator's ground truth to each state (the verdict's judge)."""


class FrankaWrenchFt(DeviceConfig):
    """The Franka's external wrench estimate (``O_F_ext_hat_K``, turned into the TCF) read
    as an F/T sensor, one sample per ffexp cycle."""

    type: Literal["franka-wrench"] = "franka-wrench"
