"""The simulator back-end's entry: the ``sim`` F/T sensor (the world's Mini45 model) and the
``sim`` target tracker (the world's target seen like a camera), both read from the world of
a simulated robot that runs it in-process: the tracker with any robot whose table offers
``world``, the sensor with one that also offers ``world-ft`` (a robot whose own program
drains the world's F/T samples does not) (:attr:`drivers.base.backend.DeviceConfig.offers`).

The simulated robots themselves are their families' (``drivers/<family>/emulate/``). Light:
pydantic models and the entry; the drivers are imported when a rig opens them.
"""

from __future__ import annotations

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
    TrackerBackend,
    cdr_topics_of,
    needs_offer,
)
from drivers.config import NonNeg
from drivers.errors import ConfigError

if TYPE_CHECKING:
    from drivers.world.world import SimWorld

__all__ = ["BACKEND", "SimFt", "SimTrackerConfig"]


class SimFt(DeviceConfig):
    """The simulated Mini45 of the simulated robot's world."""

    type: Literal["sim"] = "sim"


class SimTrackerConfig(DeviceConfig):
    """The simulated target's pose as a camera would report it (a simulated robot's world)."""

    type: Literal["sim"] = "sim"
    rate_hz: Annotated[float, Field(gt=0.0)] = 50.0
    """Frames per second (the paper's camera: 50 fps)."""
    latency_s: NonNeg = 0.03
    """From exposure to the pose being available."""
    position_noise_m: NonNeg = 0.0003
    """Standard deviation of each frame's position error, per horizontal axis (per axis
    for a target in free flight) [m]."""
    yaw_noise_deg: NonNeg = 0.1
    """Standard deviation of each frame's yaw error (of its turn about each axis for a
    target in free flight) [deg]."""
    dropout: Annotated[float, Field(ge=0.0, le=1.0)] = 0.0
    """Fraction of frames without a pose (marker not found)."""


def _world(robot: OpenedRobot, ctx: OpenContext, table: str) -> SimWorld:
    """The simulated robot's world (the simulated sensor and tracker read it)."""
    from drivers.world.world import SimWorld

    world = getattr(robot.robot, "world", None)
    if not isinstance(world, SimWorld):  # the rig's check makes this unreachable
        raise ConfigError(ctx.source, f"{table}.type", "needs a simulated robot in-process")
    return world


def _open_ft(cfg: SimFt, ctx: OpenContext, robot: OpenedRobot) -> OpenedSensor:
    from drivers.world.ftstream import SimFtSensor

    return OpenedSensor(SimFtSensor(_world(robot, ctx, "ft")))


def _open_tracker(cfg: SimTrackerConfig, ctx: OpenContext, robot: OpenedRobot) -> OpenedTracker:
    from drivers.sim.tracker import SimTracker

    world = _world(robot, ctx, "tracker")
    tracker = SimTracker(world, lambda: world.cycle * world.cycle_ns, rate_hz=cfg.rate_hz,
                         latency_s=cfg.latency_s, position_noise_m=cfg.position_noise_m,
                         yaw_noise_deg=cfg.yaw_noise_deg, dropout=cfg.dropout, seed=ctx.seed)
    return OpenedTracker(tracker)


#: The F/T model goes with a robot that leaves the world's samples to it.
_check_ft = needs_offer("ft", "world-ft", hint="over a link the simulated sensor is served "
                        "by the emulator: use 'netft'")
#: The tracker watches the world of a robot that runs it in-process (it has ``world``).
_check_tracker = needs_offer("tracker", "world", hint="over a link the emulator serves "
                             "a camera stream: use 'camera'")


BACKEND = Backend(
    "sim",
    sensors=(FtBackend(SimFt, _open_ft, _check_ft),),
    trackers=(TrackerBackend(SimTrackerConfig, _open_tracker, _check_tracker),),
    topics=cdr_topics_of("drivers.world.topics"),
)
