"""The KUKA LWR4+ family's entry: the ``fri1`` robot (a KUKA KRC2 LR over FRI 1.x on UDP), the
``sim`` robot (the simulated LWR4+ in-process: the lockstep KRC of
:mod:`drivers.fri.emulate.lockstep` in front of the simulator's world), the ``fri-estimate``
F/T source (the KRC's own external-wrench estimate) and the ``lwr4`` controller ``ffexp
emulate`` serves (:mod:`drivers.fri.emulate`).

It states what ``ffexp`` reads of FRI's topics without naming them: the link-fault
counters (the UDP driver's own on ``/robot/link_driver``, the KRC's misses on
``/robot/link``), the link's statistics, and where the applied command is recorded
(:data:`FRI_COMMANDS`, which the simulated LWR4+ replays).

:class:`FriRobotConfig` (:mod:`drivers.fri.config`) is the rig's ``[robot]`` table and what
:class:`~drivers.fri.driver.FriRobot` takes; its errors name the rig's fields.
Light: the driver is imported when a rig opens it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from drivers.base.backend import (
    Backend,
    CommandFields,
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
from drivers.fri.config import FriEstimateFt, FriRobotConfig, SimRobotConfig

if TYPE_CHECKING:
    from drivers.description.scene import Scene

__all__ = ["BACKEND", "FRI_COMMANDS", "FriEstimateFt", "FriRobotConfig", "SimRobotConfig"]

#: Where FRI back-ends record the command packet the KRC applied (``tFriCmdData``).
FRI_COMMANDS = CommandFields("/robot/command", pose="cart_pos", stiffness="cart_stiffness",
                             damping="cart_damping", wrench="add_tcp_ft")

_DRIVER = "/robot/link_driver"  # the UDP driver's own counters (cumulative since connect)
_KRC = "/robot/link"  # the KRC's view of the link

#: Faults on the link: the UDP driver's counters, then the answers the KRC missed (its
#: counter restarts with the KRC).
LINK_FAULTS = (
    LinkCounter(_DRIVER, "lost", "measurements lost"),
    LinkCounter(_DRIVER, "duplicates", "duplicate measurements"),
    LinkCounter(_DRIVER, "reordered", "reordered measurements"),
    LinkCounter(_DRIVER, "rejected", "malformed datagrams"),
    LinkCounter(_DRIVER, "implausible", "implausible measurements"),
    LinkCounter(_DRIVER, "restarts", "sequence restarts"),
    LinkCounter(_DRIVER, "skipped", "measurements the runner skipped"),
    LinkCounter(_DRIVER, "deadline_answers", "cycles answered late (deadline repeat)"),
    LinkCounter(_DRIVER, "runner_late", "late runner commands"),
    LinkCounter(_DRIVER, "foreign", "datagrams from another address"),
    LinkCounter(_KRC, "miss_counter", "answers the KRC missed", key="krc_missed"),
)

#: The KRC's view of the link, summarised per run.
LINK_STATS = (
    LinkStat("cycles", _KRC, "quality", "count"),
    LinkStat("min_answer_rate", _KRC, "answer_rate", "min"),
    LinkStat("max_latency_s", _KRC, "latency_s", "max"),
    LinkStat("max_jitter_s", _KRC, "jitter_s", "max"),
    LinkStat("miss_counter", _KRC, "miss_counter", "last"),
    LinkStat("fraction_below_ok", _KRC, "quality", "fraction_below", below=2),  # OK = 2
)


def _open_robot(cfg: FriRobotConfig, ctx: OpenContext) -> OpenedRobot:
    from drivers.fri.driver import FriRobot

    robot = FriRobot(cfg, where=ctx.where("robot"))
    try:
        host, port = robot.bind()  # a port in use is reported before anything is recorded
    except BaseException:
        robot.close()
        raise
    return OpenedRobot(
        robot, robot.now_ns, robot.robot_ip,
        {"driver": "fri1", "robot_ip": robot.robot_ip, "fri_port": str(port)},
        notice=f"fri: listening on {host}:{port} for the KRC at {robot.robot_ip}",
    )


def _open_estimate(cfg: FriEstimateFt, ctx: OpenContext, robot: OpenedRobot) -> OpenedSensor:
    from drivers.fri.estimate import FriEstimateSensor, MeasurementSource

    source = robot.robot
    if not isinstance(source, MeasurementSource):  # the rig's check makes this unreachable
        raise TypeError(f"{type(source).__name__} reports no FRI measurements")
    return OpenedSensor(FriEstimateSensor(source), note="F/T from estExtTcpFT")


def _sim_scene(cfg: SimRobotConfig, ctx: OpenContext) -> Scene:
    from drivers.description import load_scene

    return load_scene(ctx.scene_path(cfg.scene_file), ctx.scene_overrides)


def _open_sim(cfg: SimRobotConfig, ctx: OpenContext) -> OpenedRobot:
    from drivers.fri.emulate.lockstep import open_rig_robot

    return open_rig_robot(cfg, ctx, ctx.scene_path(cfg.scene_file), _sim_scene(cfg, ctx))


def _replay_table(start_cycles: int, wire_precision: bool) -> dict[str, Any]:
    return {"type": "sim", "start_cycles": start_cycles, "wire_precision": wire_precision}


def _krc_cycle_s(scene: Scene) -> float:
    return scene.fri.cycle


#: The simulated LWR4+ replays recordings of an LWR4+ behind a KRC, simulated or real
#: (the commands FRI records); a real one's crossed FRI's float32 wire.
_REPLAY = Replay(robots=("sim", "fri1"), commands=FRI_COMMANDS, table=_replay_table,
                 cycle_s=_krc_cycle_s, wire=("fri1",), estimate_ft=("fri-estimate",))

#: ``ffexp emulate --robot lwr4``: a KRC2 LR sending FRI datagrams to ``--remote``.
EMULATOR = Emulator("lwr4", "a KRC2 LR over FRI 1.x (sends to --remote)",
                    serve="drivers.fri.emulate.served:serve", takes_cycle=True, ft_box=True,
                    camera=True)


BACKEND = Backend(
    "fri",
    robots=(RobotBackend(SimRobotConfig, _open_sim, driver="sim", default_ft="sim",
                         scene=_sim_scene, replay=_REPLAY, arm="lwr4"),
            RobotBackend(FriRobotConfig, _open_robot, driver="fri", default_ft="netft",
                         arm="lwr4")),
    sensors=(FtBackend(FriEstimateFt, _open_estimate, needs_robot("ft", "fri1", "sim")),),
    topics=cdr_topics_of("drivers.fri.topics"),
    link_faults=LINK_FAULTS,
    link_stats=LINK_STATS,
    emulators=(EMULATOR,),
)
