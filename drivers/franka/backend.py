"""The Franka family's entry: the ``franka`` robot (an FR3 or Panda over libfranka, real, or
``ffexp emulate --robot fr3``, or any FCI server), the ``franka-sim`` robot (the simulated
FR3 in-process: ffexp's driver on the FR3's controller in lockstep,
:mod:`drivers.franka.emulate.lockstep`), the ``franka-wrench`` F/T source (the robot's
external wrench estimate) and the ``fr3`` controller ``ffexp emulate`` serves
(:mod:`drivers.franka.emulate`).

The real robot needs ``pylibfranka`` (the optional extra ``franka``: ``pip install
'ffexp[franka]'``; wheels for Python 3.9-3.12 on Linux x86_64 only), imported when a
Franka rig opens; without it the rig fails with one line. Light: the driver is imported
when a rig opens it.
"""

from __future__ import annotations

import sys
from importlib.util import find_spec
from typing import TYPE_CHECKING, Any

from drivers.base.backend import (
    RUNNER_APPLIED,
    Backend,
    Emulator,
    FtBackend,
    LinkCounter,
    LinkStat,
    OpenContext,
    OpenedRobot,
    OpenedSensor,
    Replay,
    RobotBackend,
    cdr_topics_of,
    needs_robot,
)
from drivers.errors import ConfigError
from drivers.franka.config import FrankaSettings, FrankaSimConfig, FrankaWrenchFt

if TYPE_CHECKING:
    from drivers.description.scene import Scene

__all__ = ["APPLIED_COMMANDS", "BACKEND", "FrankaSettings", "FrankaSimConfig",
           "FrankaWrenchFt"]

_TOPIC = "/robot/franka"


def _need_pylibfranka(ctx: OpenContext) -> None:
    if find_spec("pylibfranka") is not None:
        return
    py = f"{sys.version_info.major}.{sys.version_info.minor}"
    why = ("pylibfranka has no wheel for Python " + py + " (3.9-3.12 only)"
           if sys.version_info >= (3, 13) else "install the extra: pip install 'ffexp[franka]'")
    raise ConfigError(ctx.source, "robot.type", f"'franka' needs pylibfranka: {why}")


def _open_robot(cfg: FrankaSettings, ctx: OpenContext) -> OpenedRobot:
    from drivers.franka.driver import FrankaRobot
    from drivers.net.udp import resolve_ipv4

    _need_pylibfranka(ctx)
    resolve_ipv4(f"{ctx.where('robot')}.robot_ip", cfg.robot_ip)
    robot = FrankaRobot(cfg, where=ctx.where("robot"))
    return OpenedRobot(
        robot, robot.now_ns, cfg.robot_ip,
        {"driver": "franka", "robot_ip": cfg.robot_ip,
         "setpoint_every": str(cfg.setpoint_every)},
        notice=f"franka: libfranka's torque loop with {cfg.robot_ip}, the set-point every "
               f"{cfg.setpoint_every} ms")


def _sim_scene(cfg: FrankaSimConfig, ctx: OpenContext) -> Scene:
    from drivers.description.fr3 import FR3, PAPER_SCENE_OVERRIDES
    from drivers.description.swap import scene_with_arm

    return scene_with_arm(ctx.scene_path(cfg.scene_file), ctx.scene_overrides, FR3,
                          PAPER_SCENE_OVERRIDES)


def _open_sim(cfg: FrankaSimConfig, ctx: OpenContext) -> OpenedRobot:
    from drivers.franka.emulate.lockstep import open_sim

    return open_sim(cfg, ctx, ctx.scene_path(cfg.scene_file), _sim_scene(cfg, ctx))


def _open_wrench(cfg: FrankaWrenchFt, ctx: OpenContext, robot: OpenedRobot) -> OpenedSensor:
    from drivers.franka.driver import FrankaRobot
    from drivers.franka.wrench import FrankaWrenchSensor

    source = robot.robot
    if not isinstance(source, FrankaRobot):  # the rig's check makes this unreachable
        raise TypeError(f"{type(source).__name__} is not a Franka")
    return OpenedSensor(FrankaWrenchSensor(source), note="F/T from the Franka's O_F_ext_hat_K")


#: Where a Franka's recordings hold the set-point its driver's law applied (the stiffness
#: clipped to the law's limits; a held cycle kept the law's set-point): the runner's own
#: record, :data:`~drivers.base.backend.RUNNER_APPLIED` (no wire carries the set-point).
APPLIED_COMMANDS = RUNNER_APPLIED


def _replay_table(start_cycles: int, wire_precision: bool) -> dict[str, Any]:
    # the law commands from the first state; the set-point crosses no wire
    return {"type": "franka-sim"}


def _setpoint_cycle_s(scene: Scene) -> float:
    """ffexp's cycle on the simulated FR3: the table's default ``setpoint_every`` world
    steps (the scene's ``fri.cycle``: the FCI's torque cycle)."""
    every = int(FrankaSimConfig.model_fields["setpoint_every"].default)
    return scene.fri.cycle * every


#: The simulated FR3 replays recordings of a Franka, real or simulated, through the same
#: driver and impedance law with the recorded rig's law settings (its ``setpoint_every``
#: the table's default: a recording at another is refused by its cycle); the robot's own
#: wrench estimate (``franka-wrench``) is replayed as it is.
_REPLAY = Replay(robots=("franka-sim", "franka"), commands=APPLIED_COMMANDS,
                 table=_replay_table, cycle_s=_setpoint_cycle_s,
                 estimate_ft=("franka-wrench",),
                 settings=("stiffness_max_npm_nmprad", "hold_stiffness_npm_nmprad",
                           "nullspace_stiffness_nmprad", "nullspace_damping_nmsprad"))


#: ``ffexp emulate --robot fr3``: an FR3 listening on libfranka's command port.
EMULATOR = Emulator("fr3", "a Franka FR3 over libfranka's protocol (listens on --listen, "
                    "default 127.0.0.1:1337)", serve="drivers.franka.emulate.served:serve",
                    listen=("127.0.0.1", 1337),
                    overrides_from="drivers.description.fr3:PAPER_SCENE_OVERRIDES",
                    faults=(("silence", "1: accept connections but never answer"),
                            ("version", "answer the connection with this server version"),
                            ("drop_after", "close the connection after this many ms "
                             "of a motion (0: never)"),
                            ("reflex_after", "a cartesian_reflex after this many ms of a "
                             "motion (0: never)")))

BACKEND = Backend(
    "franka",
    robots=(RobotBackend(FrankaSettings, _open_robot, driver="franka",
                         default_ft="franka-wrench", arm="fr3", takes_arm_place=True),
            RobotBackend(FrankaSimConfig, _open_sim, driver="franka-sim", default_ft="sim",
                         scene=_sim_scene, replay=_REPLAY, arm="fr3",
                         takes_arm_place=True)),
    sensors=(FtBackend(FrankaWrenchFt, _open_wrench,
                       needs_robot("ft", "franka", "franka-sim")),),
    topics=cdr_topics_of("drivers.franka.topics"),
    link_faults=(LinkCounter(_TOPIC, "missed_cycles", "1 kHz cycles the driver missed"),),
    link_stats=(LinkStat("min_success_rate", _TOPIC, "success_rate", "min"),),
    emulators=(EMULATOR,),
)
