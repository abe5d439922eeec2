"""One run end to end: rig + protocol file -> devices (factory) -> loop -> one MCAP file.

Also reads a campaign file (:func:`load_campaign`); running one is
:func:`ffexp.campaign.run_campaign`. The CLI is a thin layer over both.
"""

from __future__ import annotations

import json
import platform
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from functools import cache
from importlib import metadata as importlib_metadata
from pathlib import Path
from typing import TYPE_CHECKING

from drivers import registry
from drivers.config import apply_overrides, read_toml
from drivers.description import load_scene
from drivers.factory import Devices, open_devices, robot_arm
from drivers.rig import Rig, load_rig, validate_rig
from ffexp import __version__, loop
from ffexp.contracts import Progress, RunOutcome
from ffexp.errors import ConfigError, FfexpError, InputError
from ffexp.filekind import load_as, named_kind
from ffexp.live.address import LiveOptions
from ffexp.naming import overrides_id, reserve, run_stem
from ffexp.protocol import CampaignProtocol, RunProtocol, load_run_protocol, scene_path
from ffexp.recording import Recorder
from ffexp.revision import source_revision
from ffexp.rig_choice import DEFAULT_DRIVER, DRIVERS, FT_SOURCES, RigChoice
from ffexp.runlog import RunLog

if TYPE_CHECKING:
    from drivers.description.scene import Scene
    from ffexp.live.server import LiveServer
    from ffexp.scene3d import SceneWriter

__all__ = [
    "DRIVERS", "FT_SOURCES", "RigChoice", "RunResult", "load_campaign", "load_rig_choice",
    "output_path", "run_file",
]


def load_rig_choice(choice: RigChoice) -> tuple[Rig, str]:
    """The rig and the name its errors use (the file, or ``<built-in DRIVER rig>``)."""
    if choice.path is not None:
        try:
            return load_rig(choice.path, choice.overrides), str(choice.path)
        except ConfigError as exc:
            raise named_kind(exc, choice.path, "rig") from None
    driver = choice.driver or DEFAULT_DRIVER
    robot = registry.robot_for_driver(driver)
    if robot is None:
        names = ", ".join(registry.driver_names())
        raise ConfigError("--driver", driver, f"unknown driver; choose one of {names}")
    source = f"<built-in {driver} rig>"
    data = {"robot": {"type": robot.rig_type}, "ft": {"type": robot.default_ft}}
    return validate_rig(apply_overrides(data, choice.overrides), source), source


@dataclass
class RunResult:
    """A finished run: how it ended and where its recording is."""

    protocol: RunProtocol
    outcome: RunOutcome
    path: Path


def _versions(revision: str) -> str:
    out = {
        "ffexp": __version__, "source_revision": revision,
        "python": sys.version.split()[0],
    }
    out.update(_dist_versions())
    return json.dumps(out)


@cache
def _dist_versions() -> tuple[tuple[str, str], ...]:
    """The libraries' versions, read once per process: a loaded module's ``__version__``
    (the run has imported them all), else its distribution's metadata
    (``importlib.metadata`` scans the path for each: ~8 ms for the six)."""
    out = []
    for dist in ("numpy", "mujoco", "mcap", "filterpy", "pydantic", "scipy"):
        version = getattr(sys.modules.get(dist), "__version__", None)
        if isinstance(version, str):
            out.append((dist, version))
            continue
        try:
            out.append((dist, importlib_metadata.version(dist)))
        except importlib_metadata.PackageNotFoundError:
            out.append((dist, "absent"))
    return tuple(out)


def _revision_beside() -> Callable[[], str]:
    """:func:`~ffexp.revision.source_revision`, started now in a thread when not known
    yet (``git describe`` runs beside the devices' set-up: ~10 ms); call the result
    for its value."""
    info = getattr(source_revision, "cache_info", None)
    if info is None or info().currsize:  # known (or not the cached function)
        return source_revision
    out: list[str] = []
    thread = threading.Thread(target=lambda: out.append(source_revision()),
                              name="source-revision", daemon=True)
    thread.start()

    def get() -> str:
        thread.join()
        return out[0] if out else source_revision()  # its error, if any, raised here

    return get


def check_arm(rig: Rig, rig_source: str, scene: Scene, scene_source: str) -> str:
    """Check that the rig's robot can drive the scene's arm (one ``error:`` line naming the
    scene's ``arm.model`` and the rig's robot when not); what happens to the scene's arm,
    in words, for the ``ffexp check`` line ("" when it is the robot's own)."""
    want, takes_place = robot_arm(rig.robot)
    have = scene.arm.model
    if want is None or have == want:
        return ""
    if takes_place:  # a robot that puts its own arm in a scene of another arm
        return f"the rig's {want} in place of the scene's {have}"
    raise ConfigError(scene_source, "arm.model", f"{have!r}, but the rig's robot "
                      f"({rig_source}: robot.type {rig.robot.type!r}) drives the {want}: "
                      f"use a scene of the {want}, or a rig of the {have}")


def output_path(
    out_dir: Path, name: str, start: datetime, overrides: list[str] | tuple[str, ...] = (),
    robot: str = "",
) -> Path:
    """``out_dir/<name>-<robot>-<overrides id>-<UTC time>.mcap`` (:mod:`ffexp.naming`), created
    empty and exclusively: never an existing file, never one another process took."""
    return reserve(out_dir, run_stem(name, overrides, start, robot), ".mcap")


def run_file(
    protocol_path: Path,
    overrides: list[str] | tuple[str, ...] = (),
    *,
    rig: RigChoice | None = None,
    out_dir: Path = Path("runs"),
    progress: Callable[[Progress], None] | None = None,
    stop_requested: Callable[[], bool] = lambda: False,
    notice: Callable[[str], None] | None = None,
    timings: dict[str, float] | None = None,
    live: LiveOptions | LiveServer | None = None,
    lean: bool = False,
) -> RunResult:
    """Run one protocol file on a rig and record it; the recording is finished even on errors.

    ``notice`` receives a line about the opened devices (where a link listens)
    before the run starts; ``timings`` collects wall time per part of the loop.
    ``live``: also serve the run to Foxglove viewers (:mod:`ffexp.live`) while it
    runs; the server stops with the run (a started :class:`~ffexp.live.LiveServer`
    given instead is fed and left to the caller to close). The recording holds the rig's 3-D scene
    (:mod:`ffexp.scene3d`).

    ``lean``: record only the topics the metrics read (:class:`~ffexp.runlog.RunLog`'s
    lean log: no F/T samples, commands, wire topics, ``/tf`` or 3-D scene; the file
    says so in its ``recording`` metadata). Its metrics are the full recording's.
    """
    protocol = load_run_protocol(protocol_path, overrides)
    revision = _revision_beside()
    rig_model, rig_source = load_rig_choice(rig or RigChoice())
    server = _live_server(live, notice) if isinstance(live, LiveOptions) else live
    try:
        scene_file = scene_path(protocol_path, protocol)
        try:
            devices = open_devices(rig_model, source=rig_source, scene_file=scene_file,
                                   scene_overrides=protocol.scene.set, seed=protocol.seed)
        except ConfigError as exc:  # a rig or protocol given as the scene: say so
            raise (named_kind(exc, scene_file, "scene") if exc.source == str(scene_file)
                   else exc) from None
        path: Path | None = None
        log: RunLog | None = None
        try:
            check_arm(rig_model, rig_source, devices.scene or load_scene(
                scene_path(protocol_path, protocol), protocol.scene.set),
                str(scene_path(protocol_path, protocol)))
            if devices.notice is not None and notice is not None:
                notice(devices.notice)
            start = datetime.now(UTC)
            start_ns = time.time_ns()
            all_overrides = [*overrides, *(f"rig:{o}" for o in (rig or RigChoice()).overrides)]
            try:
                path = output_path(out_dir, protocol.name, start, all_overrides,
                                   rig_model.robot.type)
            except OSError as exc:
                raise InputError(
                    f"{exc.filename or out_dir}: cannot write: {exc.strerror}") from None
            source_rev = revision()
            with Recorder(path) as rec:
                rec.metadata(
                    "run",
                    {
                        "protocol": protocol.name,
                        "method": protocol.method,
                        "protocol_file": str(protocol_path),
                        "protocol_json": protocol.model_dump_json(),
                        "overrides": json.dumps(list(overrides)),
                        "overrides_id": overrides_id(all_overrides),
                        "run_name": path.stem,
                        "source_revision": source_rev,
                        "seed": str(protocol.seed),
                        "start_utc": start.isoformat(),
                        "versions": _versions(source_rev),
                        "host": platform.node(),
                        "rig": rig_source,
                        "rig_json": rig_model.model_dump_json(),
                        **devices.metadata,
                    },
                )
                rec.attach(protocol_path.name, protocol_path.read_bytes(), "application/toml",
                           start_ns)
                for name, data in devices.attachments:
                    rec.attach(name, data, "application/toml", start_ns)
                if server is not None:
                    rec.taps.append(server.tap)
                log = RunLog(rec, start_ns, protocol.run.tf_period_s, lean=lean)
                writer = None if lean else _scene_writer(rec, protocol_path, protocol,
                                                         devices, notice)
                if writer is not None:
                    log.sinks.append(writer)
                outcome = loop.run(
                    protocol, devices.robot, devices.sensor, log, tracker=devices.tracker,
                    progress=progress,
                    stop_requested=stop_requested, timings=timings,
                )
        except FfexpError as exc:
            # refused as bad input before the robot sent anything (an address its link
            # rejects): no recording is left behind
            if exc.exit_code == 2 and path is not None and (log is None or log.cycles == 0):
                path.unlink(missing_ok=True)
            raise
        finally:
            devices.close()  # the loop closes them too; this covers failures before it runs
    finally:
        if server is not None and server is not live:
            server.close()  # publishes what is queued, then stops serving
    assert path is not None
    return RunResult(protocol, outcome, path)


def _live_server(live: LiveOptions, notice: Callable[[str], None] | None) -> LiveServer:
    from ffexp.live.server import LiveServer

    server = LiveServer(live)
    server.start()
    if notice is not None:
        notice(f"live: Foxglove WebSocket server on {server.url} "
               f"(Foxglove: Open connection, layouts/ffexp-layout.json)")
    return server


def _scene_writer(rec: Recorder, protocol_path: Path, protocol: RunProtocol, devices: Devices,
                  notice: Callable[[str], None] | None) -> SceneWriter | None:
    """The 3-D scene of the rig: the sim's own scene, else the protocol's scene file
    (a rig without a usable one records no scene, said in a notice)."""
    from drivers.description.scene import load_scene
    from ffexp.scene3d import SceneWriter

    try:
        scene = (devices.scene if devices.scene is not None
                 else load_scene(scene_path(protocol_path, protocol), protocol.scene.set))
    except ConfigError as exc:
        if notice is not None:
            notice(f"3-D scene: not recorded: {exc}")
        return None
    return SceneWriter(rec, scene, protocol.run.tf_period_s)


def load_campaign(path: Path, overrides: list[str] | tuple[str, ...] = ()) -> CampaignProtocol:
    """A campaign file; each entry's protocol path is relative to the campaign file."""
    campaign = load_as(CampaignProtocol, path, overrides, "campaign")
    for i, entry in enumerate(campaign.runs):
        p = path.parent / entry.protocol
        if not p.is_file():
            raise ConfigError(str(path), f"runs.{i}.protocol", f"{p}: file not found")
        if p.resolve() == path.resolve():
            raise ConfigError(str(path), f"runs.{i}.protocol", f"{entry.protocol} is this "
                              "campaign itself; a campaign lists run protocols")
        read_toml(p)
    return campaign
