"""Settings of the UR driver: every number of the link and of ffexp's URScript program.

The rig's ``[robot]`` table of type ``ur`` is this model as it is (a
:class:`~drivers.base.backend.DeviceConfig`: unknown keys are errors; the entry is
:mod:`drivers.ur.backend`), and :class:`~drivers.ur.driver.UrRobot` takes it.
Defaults are UR's own where UR documents one (URScript manual:
force_mode_set_damping 0.005, gain scaling 1, servoj lookahead 0.1 s and gain 300)
and e-Series rates (RTDE Guide: 500 Hz; 125 Hz on a CB3).
"""

from __future__ import annotations

from pathlib import Path
from typing import ClassVar, Literal

from pydantic import Field

from drivers.base.backend import DeviceConfig
from drivers.config import Vec6


class UrSettings(DeviceConfig):
    """Where the UR controller is and how ffexp drives it."""

    type: Literal["ur"] = "ur"
    robot_ip: str = Field(description="the controller's address (IPv4 or host name)")
    rtde_port: int = Field(30004, ge=1, le=65535,
                           description="RTDE port (30004 on a real controller)")
    frequency_hz: float = Field(500.0, gt=0.0, le=500.0,
                                description="output rate: 500 on e-Series, 125 on CB3")
    connect_timeout_s: float = Field(2.0, gt=0.0, description="longest wait for an answer "
                                     "while connecting")
    cycle_timeout_s: float = Field(0.1, gt=0.0, description="longest gap between data "
                                   "packages before the link is lost")
    script: Literal["send", "installed"] = Field(
        "send", description="send drivers/ur/ffexp_control.script over the script port at "
        "connect, or expect it installed and running (docs/ur.md)")
    script_port: int = Field(30002, ge=1, le=65535,
                             description="the controller's port that takes URScript")
    force_axis_stiffness_npm_nmprad: float = Field(
        0.0, ge=0.0, description="an axis commanded at most this stiff is compliant "
        "(force mode); the others follow the pose")
    force_mode_damping: float = Field(0.005, ge=0.0, le=1.0,
                                      description="force_mode_set_damping, 0..1")
    force_mode_gain_scaling: float = Field(1.0, ge=0.0, le=2.0,
                                           description="force_mode_set_gain_scaling, 0..2")
    compliant_speed_limits_mps_radps: Vec6 = Field(
        (0.1, 0.1, 0.1, 0.5, 0.5, 0.5),
        description="force mode's speed cap on compliant axes [m/s, rad/s]")
    deviation_limits_m_rad: Vec6 = Field(
        (0.05, 0.05, 0.05, 0.17, 0.17, 0.17),
        description="force mode's deviation cap on the other axes [m, rad]")
    servo_lookahead_s: float = Field(0.1, ge=0.03, le=0.2,
                                     description="servoj lookahead time")
    servo_gain: float = Field(300.0, ge=100.0, le=2000.0, description="servoj gain")


class UrSimConfig(UrSettings):
    """The simulated UR5e in-process (lockstep, no sockets), with a real UR's force-mode
    settings (``robot_ip``, the ports and ``script`` are not used)."""

    type: Literal["ur-sim"] = "ur-sim"  # type: ignore[assignment]
    #: it runs the world in-process; its program drains the world's F/T samples itself
    offers: ClassVar[frozenset[str]] = frozenset({"world"})
    robot_ip: str = "127.0.0.1"
    scene_file: Path | None = None
    """Scene TOML of a UR arm (relative to the rig file); default: the protocol's scene."""
    truth: bool = True
    """Attach the simulator's ground truth to each state (the verdict's judge); false:
    as over RTDE, where the verdict comes from a tracker or the observer."""
