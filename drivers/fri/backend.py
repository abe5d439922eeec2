"""The FRI back-end's entry: the ``fri1`` robot (a KUKA KRC2 LR over FRI 1.x on UDP) and the
``fri-estimate`` F/T source (the KRC's own external-wrench estimate).

:class:`FriRobotConfig` is the rig's ``[robot]`` table and what
:class:`~drivers.fri.driver.FriRobot` takes; its errors name the rig's fields.
Light: the driver is imported when a rig opens it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Annotated, Literal

from pydantic import Field

from drivers.base.backend import (
    Backend,
    DeviceConfig,
    FtBackend,
    OpenContext,
    OpenedRobot,
    OpenedSensor,
    RobotBackend,
)

if TYPE_CHECKING:
    from drivers.base.topics import CdrTopic

__all__ = ["BACKEND", "FriEstimateFt", "FriRobotConfig"]

Port = Annotated[int, Field(ge=0, le=65535)]
PosFloat = Annotated[float, Field(gt=0.0)]


class FriRobotConfig(DeviceConfig):
    """A KUKA KRC2 LR over FRI 1.x (UDP): where the KRC is and how to answer it."""

    type: Literal["fri1"] = "fri1"
    robot_ip: str
    """The KRC's address (IPv4 or host name); packets from anywhere else are dropped."""
    port: Port = 49938
    """Local UDP port (``FRISOCK`` in the KRC's dlrrc.ini; 0 = any free port)."""
    bind_host: str = "0.0.0.0"
    """Local address to bind."""
    robot_port: Annotated[int, Field(ge=1, le=65535)] | None = None
    """If set, also require this source port."""
    answer_deadline_cycles: Annotated[float, Field(ge=0.0)] = 0.5
    """Latest answer, in cycles after the packet arrived; 0 answers on arrival."""
    follow_lockstep_marker: bool = True
    """Wait for the runner when the emulator says lockstep."""
    connect_timeout_s: PosFloat = 10.0
    """Longest wait for the first measurement."""
    cycle_timeout_s: PosFloat = 1.0
    """Longest gap between measurements before the link is lost."""
    runner_timeout_s: PosFloat = 5.0
    """In lockstep, longest wait for the runner's command."""
    poll_s: PosFloat = 0.05
    """How often the I/O thread wakes up to notice ``close()``."""
    restart_seq_jump: Annotated[int, Field(ge=1)] = 100
    """A measurement older than this many cycles is a KRC restart, not reordering."""
    min_cycle_s: PosFloat = 0.0009
    """Shortest plausible cycle (friOpen takes 1..100 ms); shorter packets are dropped."""
    max_cycle_s: PosFloat = 0.101
    """Longest plausible cycle."""


class FriEstimateFt(DeviceConfig):
    """The KRC's own estimate of the external wrench (``estExtTcpFT``), one sample per cycle."""

    type: Literal["fri-estimate"] = "fri-estimate"


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


def _check_estimate(cfg: FriEstimateFt, robot: DeviceConfig) -> str | None:
    if robot.type in ("fri1", "sim"):
        return None
    return "ft.type 'fri-estimate' needs robot.type 'fri1' or 'sim'"


def _topics() -> Sequence[CdrTopic]:
    from drivers.fri.topics import CDR_TOPICS

    return CDR_TOPICS


BACKEND = Backend(
    "fri",
    robots=(RobotBackend(FriRobotConfig, _open_robot, driver="fri", default_ft="netft"),),
    sensors=(FtBackend(FriEstimateFt, _open_estimate, _check_estimate),),
    topics=_topics,
)
