"""The FRI back-end's entry: the ``fri1`` robot (a KUKA KRC2 LR over FRI 1.x on UDP) and the
``fri-estimate`` F/T source (the KRC's own external-wrench estimate).

:class:`FriRobotConfig` (:mod:`drivers.fri.config`) is the rig's ``[robot]`` table and what
:class:`~drivers.fri.driver.FriRobot` takes; its errors name the rig's fields.
Light: the driver is imported when a rig opens it.
"""

from __future__ import annotations

from drivers.base.backend import (
    Backend,
    FtBackend,
    OpenContext,
    OpenedRobot,
    OpenedSensor,
    RobotBackend,
    cdr_topics_of,
    needs_robot,
)
from drivers.fri.config import FriEstimateFt, FriRobotConfig

__all__ = ["BACKEND", "FriEstimateFt", "FriRobotConfig"]


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


BACKEND = Backend(
    "fri",
    robots=(RobotBackend(FriRobotConfig, _open_robot, driver="fri", default_ft="netft"),),
    sensors=(FtBackend(FriEstimateFt, _open_estimate, needs_robot("ft", "fri1", "sim")),),
    topics=cdr_topics_of("drivers.fri.topics"),
)
