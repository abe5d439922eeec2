"""A whole run over UDP against the stand-in KRC (the FRI emulator), in one process.

The remote driver (:class:`FriRobot`) and the emulator (lockstep unless asked
otherwise, with injected faults) talk on loopback; the loop runs a protocol
with the KRC's own wrench estimate as the F/T sensor and records into an MCAP
file, which is loaded back. Used by ``tests/test_link_truth.py``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from drivers.description.scene import load_scene
from drivers.emulate.faults import FaultSettings
from drivers.fri.backend import FriRobotConfig
from drivers.fri.driver import FriEstimateSensor, FriRobot
from drivers.fri.emulate.server import EmulatorSettings, EmulatorStats, FriEmulator
from drivers.fri.link import QualityThresholds
from drivers.world.world import SimWorld
from ffexp import loop
from ffexp.contracts import RunOutcome
from ffexp.protocol import load_run_protocol
from ffexp.recording import Recorder, load
from ffexp.recording.reader import Recording
from ffexp.runlog import RunLog

ROOT = Path(__file__).resolve().parents[1]
PROTOCOL = ROOT / "protocols" / "method1_case1.toml"
LOCAL = "127.0.0.1"


@dataclass
class LinkRun:
    outcome: RunOutcome
    rec: Recording
    emu: EmulatorStats
    path: Path


def emulated_run(tmp: Path, overrides: list[str], *, faults: FaultSettings | None = None,
                 pacing: str = "lockstep", connect_timeout_s: float = 5.0,
                 cycle_timeout_s: float = 1.0, lockstep_timeout_s: float = 0.5,
                 silent: bool = False, robot_ip: str = LOCAL,
                 max_cycles: int | None = None,
                 quality: QualityThresholds | None = None,
                 faults_from_start: bool = False) -> LinkRun:
    """Run ``PROTOCOL`` with ``overrides`` over UDP against the emulator; load the recording.

    ``silent``: no emulator at all (a robot that never answers). ``robot_ip``:
    the address the driver expects (another one than the emulator's: a robot at
    a wrong address). ``quality``: the emulated KRC's rating (default: its own).
    ``faults_from_start``: inject from the first packet, not from the first
    ``friStart`` (which needs 100 answered cycles in a row: in real time, a loaded
    machine may never get there).
    """
    protocol = load_run_protocol(PROTOCOL, overrides)
    scene = load_scene(ROOT / "data" / "scenes" / "paper.toml")
    robot = FriRobot(FriRobotConfig(robot_ip=robot_ip, port=0, bind_host=LOCAL,
                                    connect_timeout_s=connect_timeout_s,
                                    cycle_timeout_s=cycle_timeout_s))
    sensor = FriEstimateSensor(robot)
    emu: FriEmulator | None = None
    path = tmp / "run.mcap"
    try:
        _, port = robot.bind()
        if not silent:
            emu = FriEmulator(
                SimWorld(scene, seed=protocol.seed),
                EmulatorSettings(remote=(LOCAL, port), bind_host=LOCAL,
                                 pacing="lockstep" if pacing == "lockstep" else "realtime",
                                 lockstep_timeout_s=lockstep_timeout_s,
                                 faults=faults or FaultSettings(),
                                 faults_from_start=faults_from_start,
                                 quality=quality or QualityThresholds()))
            emu.start_thread(max_cycles=max_cycles)
        with Recorder(path) as rec:
            log = RunLog(rec, time.time_ns(), protocol.run.tf_period_s)
            outcome = loop.run(protocol, robot, sensor, log)
    finally:
        if emu is not None:
            emu.close()
        robot.close()
    stats = emu.stats if emu is not None else EmulatorStats()
    return LinkRun(outcome, load(path), stats, path)
