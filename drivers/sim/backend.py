"""The simulator back-end's entry: the ``sim`` robot (the lockstep KRC in front of the MuJoCo
world, in-process), the ``sim`` F/T sensor (the world's Mini45 model) and the ``sim`` target
tracker (the world's target seen like a camera).

The sim robot is :class:`drivers.emulate.lockstep.SimRobot` (the world behind FRI's
state machine); its ``open`` imports it when called, so this folder imports no
other back-end at import time. Light: pydantic models and the entry.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Literal

from pydantic import Field

from drivers.base.backend import (
    Backend,
    DeviceConfig,
    FtBackend,
    OpenContext,
    OpenedRobot,
    OpenedSensor,
    OpenedTracker,
    RobotBackend,
    TrackerBackend,
)
from drivers.errors import ConfigError

if TYPE_CHECKING:
    from drivers.sim.world import SimWorld

__all__ = ["BACKEND", "SimFt", "SimRobotConfig", "SimTrackerConfig"]

NonNeg = Annotated[float, Field(ge=0.0)]


class SimRobotConfig(DeviceConfig):
    """The simulated LWR4+ in-process (lockstep, no sockets)."""

    type: Literal["sim"] = "sim"
    start_cycles: Annotated[int, Field(ge=0)] = 100
    """Answered cycles before the link enters command mode (a friStart script: 100)."""
    max_consecutive_misses: Annotated[int, Field(ge=1)] = 5
    """Cycles without an answer in a row that end command mode."""
    scene_file: Path | None = None
    """Scene TOML (relative to the rig file); default: the protocol's scene."""
    wire_precision: bool = False
    """Round the measurement and the command through the FRI codec, as the UDP link
    does: with ``ft.type = "fri-estimate"`` a run equals the same run in lockstep
    over UDP against ``ffexp emulate``, bit for bit."""


class SimFt(DeviceConfig):
    """The simulated Mini45 of the sim robot's world."""

    type: Literal["sim"] = "sim"


class SimTrackerConfig(DeviceConfig):
    """The simulated target's pose as a camera would report it (sim robot only)."""

    type: Literal["sim"] = "sim"
    rate_hz: Annotated[float, Field(gt=0.0)] = 50.0
    """Frames per second (the paper's camera: 50 fps)."""
    latency_s: NonNeg = 0.03
    """From exposure to the pose being available."""
    position_noise_m: NonNeg = 0.0003
    """Standard deviation of each frame's position error, per horizontal axis [m]."""
    yaw_noise_deg: NonNeg = 0.1
    """Standard deviation of each frame's yaw error [deg]."""
    dropout: Annotated[float, Field(ge=0.0, le=1.0)] = 0.0
    """Fraction of frames without a pose (marker not found)."""


def _open_robot(cfg: SimRobotConfig, ctx: OpenContext) -> OpenedRobot:
    from drivers.emulate.lockstep import SimRobot
    from drivers.sim.scene import load_scene
    from drivers.sim.world import SimWorld

    path = cfg.scene_file if cfg.scene_file is not None else ctx.scene_file
    scene = load_scene(path, ctx.scene_overrides)
    world = SimWorld(scene, seed=ctx.seed)
    robot = SimRobot(world, start_cycles=cfg.start_cycles,
                     max_consecutive_misses=cfg.max_consecutive_misses,
                     wire_precision=cfg.wire_precision)
    meta = {
        "driver": "sim",
        "scene_file": str(path),
        "scene_json": scene.model_dump_json(),
        "wire_precision": str(cfg.wire_precision).lower(),
    }
    return OpenedRobot(robot, lambda: world.cycle * world.cycle_ns, None, meta,
                       [(path.name, path.read_bytes())])


def _world(robot: OpenedRobot, ctx: OpenContext, table: str) -> SimWorld:
    """The sim robot's world (the simulated sensor and tracker read it)."""
    from drivers.sim.world import SimWorld

    world = getattr(robot.robot, "world", None)
    if not isinstance(world, SimWorld):  # the rig's check makes this unreachable
        raise ConfigError(ctx.source, f"{table}.type", "needs robot.type 'sim'")
    return world


def _open_ft(cfg: SimFt, ctx: OpenContext, robot: OpenedRobot) -> OpenedSensor:
    from drivers.sim.driver import SimFtSensor

    return OpenedSensor(SimFtSensor(_world(robot, ctx, "ft")))


def _open_tracker(cfg: SimTrackerConfig, ctx: OpenContext, robot: OpenedRobot) -> OpenedTracker:
    from drivers.sim.tracker import SimTracker

    world = _world(robot, ctx, "tracker")
    tracker = SimTracker(world, lambda: world.cycle * world.cycle_ns, rate_hz=cfg.rate_hz,
                         latency_s=cfg.latency_s, position_noise_m=cfg.position_noise_m,
                         yaw_noise_deg=cfg.yaw_noise_deg, dropout=cfg.dropout, seed=ctx.seed)
    return OpenedTracker(tracker)


def _check_ft(cfg: SimFt, robot: DeviceConfig) -> str | None:
    if robot.type == "sim":
        return None
    return ("ft.type 'sim' needs robot.type 'sim' (with an FRI robot the simulated sensor "
            "is served by the emulator: use 'netft')")


def _check_tracker(cfg: SimTrackerConfig, robot: DeviceConfig) -> str | None:
    if robot.type == "sim":
        return None
    return ("tracker.type 'sim' needs robot.type 'sim' (over FRI the emulator serves a "
            "camera stream: use 'camera')")


BACKEND = Backend(
    "sim",
    robots=(RobotBackend(SimRobotConfig, _open_robot, driver="sim", default_ft="sim"),),
    sensors=(FtBackend(SimFt, _open_ft, _check_ft),),
    trackers=(TrackerBackend(SimTrackerConfig, _open_tracker, _check_tracker),),
)
