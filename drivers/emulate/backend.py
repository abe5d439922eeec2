"""The ``sim`` robot's entry: the simulated LWR4+ in-process, the lockstep KRC of
:mod:`drivers.emulate.lockstep` in front of the MuJoCo world (:mod:`drivers.sim`),
without sockets; and the ``ur-sim`` robot's: the simulated UR5e in-process, ffexp's
URScript program on the world in lockstep (:mod:`drivers.emulate.ur_lockstep`).

It lives here because the lockstep KRC combines the simulator with FRI's link
(this package is the one that may). Its F/T sensor and tracker (``[ft] type =
"sim"``, ``[tracker] type = "sim"``) are the simulator's: :mod:`drivers.sim.backend`.
Light: the world is imported when a rig opens it.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal

from pydantic import Field

from drivers.base.backend import (
    Backend,
    DeviceConfig,
    OpenContext,
    OpenedRobot,
    Replay,
    RobotBackend,
)
from drivers.fri.backend import FRI_COMMANDS
from drivers.ur.config import UrSettings

if TYPE_CHECKING:
    from drivers.description.scene import Scene

__all__ = ["BACKEND", "SimRobotConfig", "UrSimConfig"]


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


def _scene_path(cfg: SimRobotConfig | UrSimConfig, ctx: OpenContext) -> Path:
    return cfg.scene_file if cfg.scene_file is not None else ctx.scene_file


def _sim_scene(cfg: SimRobotConfig, ctx: OpenContext) -> Scene:
    from drivers.description import load_scene

    return load_scene(_scene_path(cfg, ctx), ctx.scene_overrides)


def _open_robot(cfg: SimRobotConfig, ctx: OpenContext) -> OpenedRobot:
    from drivers.emulate.lockstep import SimRobot
    from drivers.sim.world import SimWorld

    path = _scene_path(cfg, ctx)
    scene = _sim_scene(cfg, ctx)
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
                       [(path.name, path.read_bytes())], scene=scene)


def _replay_table(start_cycles: int, wire_precision: bool) -> dict[str, Any]:
    return {"type": "sim", "start_cycles": start_cycles, "wire_precision": wire_precision}


def _krc_cycle_s(scene: Scene) -> float:
    return scene.fri.cycle


#: The simulated LWR4+ replays recordings of an LWR4+ behind a KRC, simulated or real
#: (the commands FRI records); a real one's crossed FRI's float32 wire.
_REPLAY = Replay(robots=("sim", "fri1"), commands=FRI_COMMANDS, table=_replay_table,
                 cycle_s=_krc_cycle_s, wire=("fri1",), estimate_ft=("fri-estimate",))


class UrSimConfig(UrSettings):
    """The simulated UR5e in-process (lockstep, no sockets), with a real UR's force-mode
    settings (``robot_ip``, the ports and ``script`` are not used)."""

    type: Literal["ur-sim"] = "ur-sim"  # type: ignore[assignment]
    robot_ip: str = "127.0.0.1"
    scene_file: Path | None = None
    """Scene TOML of a UR arm (relative to the rig file); default: the protocol's scene."""
    truth: bool = True
    """Attach the simulator's ground truth to each state (the verdict's judge); false:
    as over RTDE, where the verdict comes from a tracker or the observer."""


def _ur_scene(cfg: UrSimConfig, ctx: OpenContext) -> Scene:
    from drivers.description import load_scene
    from drivers.description.ur5e import PAPER_SCENE_OVERRIDES

    path = _scene_path(cfg, ctx)
    scene = load_scene(path, ctx.scene_overrides)
    if scene.arm.model != "ur5e":  # an LWR4+ scene (the protocol's): the UR5e in its place
        scene = load_scene(path, (*PAPER_SCENE_OVERRIDES, *ctx.scene_overrides))
    return scene


def _open_ur(cfg: UrSimConfig, ctx: OpenContext) -> OpenedRobot:
    from drivers.emulate.ur_lockstep import SimUrRobot
    from drivers.sim.world import SimWorld

    path = _scene_path(cfg, ctx)
    scene = _ur_scene(cfg, ctx)
    world = SimWorld(scene, seed=ctx.seed)
    robot = SimUrRobot(world, cfg, where=ctx.where("robot"))
    meta = {"driver": "ur-sim", "scene_file": str(path), "scene_json": scene.model_dump_json()}
    return OpenedRobot(robot, lambda: world.cycle * world.cycle_ns, None, meta,
                       [(path.name, path.read_bytes())], scene=scene)


BACKEND = Backend(
    "emulate",
    robots=(RobotBackend(SimRobotConfig, _open_robot, driver="sim", default_ft="sim",
                         scene=_sim_scene, replay=_REPLAY),
            RobotBackend(UrSimConfig, _open_ur, driver="ur-sim", default_ft="ur-wrench",
                         scene=_ur_scene)),
)
