"""One run end to end: protocol file -> drivers -> Runner -> one MCAP file.

Also the campaign (several protocols in a row). The CLI is a thin layer over
:func:`run_file` and :func:`run_campaign`.
"""

from __future__ import annotations

import json
import platform
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from importlib import metadata as importlib_metadata
from pathlib import Path

from drivers.base.interfaces import ForceTorqueSensor, RobotDriver
from drivers.config import load_model, read_toml
from drivers.sim.driver import open_sim
from drivers.sim.scene import load_scene
from ffexp import __version__
from ffexp.errors import ConfigError
from ffexp.protocol import CampaignProtocol, RunProtocol, load_run_protocol, scene_path
from ffexp.recording import Recorder
from ffexp.runner import Progress, Runner, RunOutcome

DRIVERS = ("sim", "fri")
#: F/T back-ends: the in-process sim sensor, an ATI Net F/T box (or the
#: emulator's), or the KRC's estExtTcpFT.
FT_SOURCES = ("sim", "netft", "fri-estimate")


@dataclass(frozen=True)
class LinkOptions:
    """How ``--driver fri`` reaches the robot and the F/T sensor (``ffexp run`` options).

    Args:
        robot_ip: the KRC's address (``--robot-ip``); packets from elsewhere are dropped.
        fri_port: local UDP port (``--fri-port``; FRISOCK in the KRC's dlrrc.ini; 0 = any).
        ft: ``auto`` (sim for the sim driver, netft for fri), ``sim``, ``netft``, ``fri-estimate``.
        netft: ``HOST:PORT`` of the Net F/T box (default: the robot's host, port 49152).
        answer_deadline: FRI answer deadline in cycles (see drivers.fri.driver).
    """

    robot_ip: str | None = None
    fri_port: int = 49938
    ft: str = "auto"
    netft: str | None = None
    answer_deadline: float = 0.5


@dataclass
class RunResult:
    """A finished run: how it ended and where its recording is."""

    protocol: RunProtocol
    outcome: RunOutcome
    path: Path


def _versions() -> str:
    out = {"ffexp": __version__, "python": sys.version.split()[0]}
    for dist in ("numpy", "mujoco", "mcap", "filterpy", "pydantic", "scipy"):
        try:
            out[dist] = importlib_metadata.version(dist)
        except importlib_metadata.PackageNotFoundError:
            out[dist] = "absent"
    return json.dumps(out)


def open_drivers(
    driver: str, protocol_path: Path, protocol: RunProtocol, link: LinkOptions | None = None
) -> tuple[RobotDriver, ForceTorqueSensor, dict[str, str], list[tuple[str, bytes]]]:
    """The robot/sensor pair for ``driver``, run metadata about it, files to attach.

    For ``fri`` the UDP ports are bound here, so that a port in use or a bad
    address is reported before anything is recorded.
    """
    link = link if link is not None else LinkOptions()
    ft = link.ft
    if ft not in ("auto", *FT_SOURCES):
        raise ConfigError("--ft", ft, f"unknown F/T source; choose one of {', '.join(FT_SOURCES)}")
    if driver == "sim" and ft not in ("auto", "sim"):
        raise ConfigError("--ft", ft, "--driver sim has only the simulated sensor (--ft sim)")
    if driver == "fri":
        return _open_fri(link)
    if driver == "sim":
        spath = scene_path(protocol_path, protocol)
        scene = load_scene(spath, protocol.scene.set)
        robot, sensor = open_sim(scene, seed=protocol.seed)
        meta = {
            "driver": "sim",
            "scene_file": str(spath),
            "scene_json": scene.model_dump_json(),
        }
        return robot, sensor, meta, [(spath.name, spath.read_bytes())]
    raise ConfigError("--driver", driver, f"unknown driver; choose one of {', '.join(DRIVERS)}")


def _open_fri(
    link: LinkOptions,
) -> tuple[RobotDriver, ForceTorqueSensor, dict[str, str], list[tuple[str, bytes]]]:
    from drivers.fri.driver import FriEstimateSensor, FriRobot, FriSettings
    from drivers.fri.udp import parse_host, parse_host_port
    from drivers.netft.client import NetFtClient, NetFtSettings

    if not link.robot_ip:
        raise ConfigError("--robot-ip", "", "required with --driver fri (the KRC's address)")
    ft = "netft" if link.ft == "auto" else link.ft
    if ft == "sim":
        raise ConfigError(
            "--ft", "sim", "with --driver fri the simulated sensor lives in the emulator: use "
            "--ft netft (ffexp emulate serves it as a Net F/T box) or --ft fri-estimate",
        )
    robot_ip = parse_host("--robot-ip", link.robot_ip)
    robot = FriRobot(
        FriSettings(robot_ip=robot_ip, port=link.fri_port, answer_deadline=link.answer_deadline)
    )
    host, port = robot.bind()
    meta = {"driver": "fri", "robot_ip": robot_ip, "fri_port": str(port), "ft": ft}
    sensor: ForceTorqueSensor
    if ft == "netft":
        text = link.netft or f"{robot_ip}:49152"
        nhost, nport = parse_host_port("--netft", text, default_port=49152)
        client = NetFtClient(NetFtSettings(host=nhost, port=nport), clock=robot.now_ns)
        try:
            client.open()
        except BaseException:
            robot.close()
            raise
        sensor = client
        meta["netft"] = f"{nhost}:{nport}"
    else:
        sensor = FriEstimateSensor(robot)
    meta["notice"] = (
        f"fri: listening on {host}:{port} for the KRC at {robot_ip}"
        + (f"; Net F/T at {meta['netft']}" if "netft" in meta else "; F/T from estExtTcpFT")
    )
    return robot, sensor, meta, []


def output_path(out_dir: Path, name: str, start: datetime) -> Path:
    """``out_dir/<name>-<UTC time>.mcap``, never overwriting an existing file."""
    stamp = start.strftime("%Y%m%dT%H%M%S")
    path = out_dir / f"{name}-{stamp}.mcap"
    k = 1
    while path.exists():
        path = out_dir / f"{name}-{stamp}-{k}.mcap"
        k += 1
    return path


def run_file(
    protocol_path: Path,
    overrides: list[str] | tuple[str, ...] = (),
    *,
    driver: str = "sim",
    out_dir: Path = Path("runs"),
    progress: Callable[[Progress], None] | None = None,
    stop_requested: Callable[[], bool] = lambda: False,
    link: LinkOptions | None = None,
    notice: Callable[[str], None] | None = None,
) -> RunResult:
    """Run one protocol file and record it; the recording is finished even on errors.

    ``link`` configures ``--driver fri``; ``notice`` receives a line about the
    opened link (where it listens) before the run starts.
    """
    protocol = load_run_protocol(protocol_path, overrides)
    robot, sensor, driver_meta, files = open_drivers(driver, protocol_path, protocol, link)
    message = driver_meta.pop("notice", None)
    if message is not None and notice is not None:
        notice(message)
    try:
        start = datetime.now(UTC)
        start_ns = time.time_ns()
        path = output_path(out_dir, protocol.name, start)
        with Recorder(path) as rec:
            rec.metadata(
                "run",
                {
                    "protocol": protocol.name,
                    "method": protocol.method,
                    "protocol_file": str(protocol_path),
                    "protocol_json": protocol.model_dump_json(),
                    "overrides": json.dumps(list(overrides)),
                    "seed": str(protocol.seed),
                    "start_utc": start.isoformat(),
                    "versions": _versions(),
                    "host": platform.node(),
                    **driver_meta,
                },
            )
            rec.attach(protocol_path.name, protocol_path.read_bytes(), "application/toml", start_ns)
            for name, data in files:
                rec.attach(name, data, "application/toml", start_ns)
            runner = Runner(
                protocol, robot, sensor, rec, start_utc_ns=start_ns, progress=progress,
                stop_requested=stop_requested,
            )
            outcome = runner.run()
    except BaseException:
        # the runner closes the drivers; this is for failures before it runs
        sensor.stop()
        robot.close()
        raise
    return RunResult(protocol, outcome, path)


def load_campaign(path: Path, overrides: list[str] | tuple[str, ...] = ()) -> CampaignProtocol:
    """A campaign file; each entry's protocol path is relative to the campaign file."""
    campaign = load_model(CampaignProtocol, path, overrides)
    for i, entry in enumerate(campaign.runs):
        p = path.parent / entry.protocol
        if not p.is_file():
            raise ConfigError(str(path), f"runs.{i}.protocol", f"{p}: file not found")
        read_toml(p)
    return campaign
