"""The UR family's entry: the ``ur`` robot (a Universal Robots e-Series controller over RTDE,
real or ``ffexp emulate --robot ur5e``), the ``ur-sim`` robot (the simulated UR5e in-process:
ffexp's URScript program on the world in lockstep, :mod:`drivers.ur.emulate.lockstep`), the
``ur-wrench`` F/T source (the UR's own wrench) and the ``ur5e`` controller ``ffexp emulate``
serves (:mod:`drivers.ur.emulate`).

:class:`~drivers.ur.config.UrSettings` is the rig's ``[robot]`` table and what
:class:`~drivers.ur.driver.UrRobot` takes; its errors name the rig's fields. Light: the
driver is imported when a rig opens it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Literal

from drivers.base.backend import (
    RUNNER_APPLIED,
    Backend,
    DeviceConfig,
    Emulator,
    FtBackend,
    LinkCounter,
    OpenContext,
    OpenedRobot,
    OpenedSensor,
    Replay,
    RobotBackend,
    cdr_topics_of,
    needs_robot,
)
from drivers.ur.config import UrSettings, UrSimConfig

if TYPE_CHECKING:
    from drivers.description.scene import Scene

__all__ = ["APPLIED_COMMANDS", "BACKEND", "UR_ROBOT_TYPES", "UrSettings", "UrSimConfig",
           "UrWrenchFt"]

#: The robot types whose driver is a :class:`~drivers.ur.driver.UrRobot`.
UR_ROBOT_TYPES = ("ur", "ur-sim")


class UrWrenchFt(DeviceConfig):
    """The UR's own wrench read as an F/T sensor, one sample per controller cycle."""

    type: Literal["ur-wrench"] = "ur-wrench"
    source: Literal["tcp_force", "ft_raw"] = "tcp_force"
    """``tcp_force``: ``actual_TCP_force`` (payload compensated, rotated into the TCF);
    ``ft_raw``: ``ft_raw_wrench``, the flange sensor's raw reading (docs/ur.md)."""


def _open_robot(cfg: UrSettings, ctx: OpenContext) -> OpenedRobot:
    from drivers.net.udp import resolve_ipv4
    from drivers.ur.driver import UrRobot

    # an address that cannot be reached is refused here, before anything is recorded
    resolve_ipv4(f"{ctx.where('robot')}.robot_ip", cfg.robot_ip)
    robot = UrRobot(cfg, where=ctx.where("robot"))
    return OpenedRobot(
        robot, robot.now_ns, cfg.robot_ip,
        {"driver": "ur", "robot_ip": cfg.robot_ip, "rtde_port": str(cfg.rtde_port)},
        notice=f"ur: RTDE to {cfg.robot_ip}:{cfg.rtde_port} at {cfg.frequency_hz:g} Hz, "
               f"script {cfg.script}",
    )


def _open_wrench(cfg: UrWrenchFt, ctx: OpenContext, robot: OpenedRobot) -> OpenedSensor:
    from drivers.ur.driver import UrRobot
    from drivers.ur.wrench import UrWrenchSensor

    source = robot.robot
    if not isinstance(source, UrRobot):  # the rig's check makes this unreachable
        raise TypeError(f"{type(source).__name__} is not a UR")
    return OpenedSensor(UrWrenchSensor(source, cfg.source), {"ur_wrench": cfg.source},
                        f"F/T from the UR's {cfg.source}")


def _ur_scene(cfg: UrSimConfig, ctx: OpenContext) -> Scene:
    from drivers.description.swap import scene_with_arm
    from drivers.description.ur5e import PAPER_SCENE_OVERRIDES, UR5E

    return scene_with_arm(ctx.scene_path(cfg.scene_file), ctx.scene_overrides, UR5E,
                          PAPER_SCENE_OVERRIDES)


def _open_sim(cfg: UrSimConfig, ctx: OpenContext) -> OpenedRobot:
    from drivers.ur.emulate.lockstep import open_sim

    return open_sim(cfg, ctx, ctx.scene_path(cfg.scene_file), _ur_scene(cfg, ctx))


#: Where a UR's recordings hold the command its driver applied (the wrench zeroed on the
#: axes that follow the pose, as the registers carry it; a held cycle held where the arm
#: was): the runner's own record, :data:`~drivers.base.backend.RUNNER_APPLIED`.
APPLIED_COMMANDS = RUNNER_APPLIED


def _replay_table(start_cycles: int, wire_precision: bool) -> dict[str, Any]:
    # the program runs from the first data package; RTDE's doubles cross exactly
    return {"type": "ur-sim"}


def _rtde_cycle_s(scene: Scene) -> float:
    """The simulated UR's output period: whole world cycles at the table's default rate
    (:class:`~drivers.ur.emulate.lockstep.LoopbackRtde`)."""
    hz = float(UrSimConfig.model_fields["frequency_hz"].default)
    return scene.fri.cycle * max(1, round(1.0 / (scene.fri.cycle * hz)))


#: The simulated UR5e replays recordings of a UR, real or simulated, through the same
#: driver and URScript program with the recorded rig's force-mode and servo settings (its
#: rate the table's default: a recording at another is refused by its cycle); the UR's
#: own wrench (``ur-wrench``, from the recorded source) is replayed as it is.
_REPLAY = Replay(robots=("ur-sim", "ur"), commands=APPLIED_COMMANDS, table=_replay_table,
                 cycle_s=_rtde_cycle_s, estimate_ft=("ur-wrench",),
                 settings=("force_axis_stiffness_npm_nmprad", "force_mode_damping",
                           "force_mode_gain_scaling", "compliant_speed_limits_mps_radps",
                           "deviation_limits_m_rad", "servo_lookahead_s", "servo_gain"))


#: ``ffexp emulate --robot ur5e``: a UR controller listening for RTDE clients.
EMULATOR = Emulator("ur5e", "a UR e-Series controller over RTDE (listens on --listen, "
                    "default 127.0.0.1:30004)", serve="drivers.ur.emulate.served:serve",
                    listen=("127.0.0.1", 30004),
                    overrides_from="drivers.description.ur5e:PAPER_SCENE_OVERRIDES",
                    faults=(("disconnect_after", "close a client's connection after this "
                             "many data packages (0: never)"),),
                    serve_joint="drivers.ur.emulate.joint:serve",
                    joint_link="drivers.ur.joint_link:UrJointLink")


BACKEND = Backend(
    "ur",
    robots=(RobotBackend(UrSettings, _open_robot, driver="ur", default_ft="ur-wrench",
                         arm="ur5e", takes_arm_place=True),
            RobotBackend(UrSimConfig, _open_sim, driver="ur-sim", default_ft="ur-wrench",
                         scene=_ur_scene, replay=_REPLAY, arm="ur5e",
                         takes_arm_place=True)),
    sensors=(FtBackend(UrWrenchFt, _open_wrench, needs_robot("ft", *UR_ROBOT_TYPES)),),
    topics=cdr_topics_of("drivers.ur.topics"),
    # data packages the reader skipped: a cycle the runner never saw, as FRI's skipped
    link_faults=(LinkCounter("/robot/ur", "skipped_packages", "data packages the runner skipped"),),
    emulators=(EMULATOR,),
)
