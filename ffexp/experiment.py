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

DRIVERS = ("sim",)


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
    driver: str, protocol_path: Path, protocol: RunProtocol
) -> tuple[RobotDriver, ForceTorqueSensor, dict[str, str], list[tuple[str, bytes]]]:
    """The robot/sensor pair for ``driver``, run metadata about it, files to attach."""
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
) -> RunResult:
    """Run one protocol file and record it; the recording is finished even on errors."""
    protocol = load_run_protocol(protocol_path, overrides)
    robot, sensor, driver_meta, files = open_drivers(driver, protocol_path, protocol)
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
