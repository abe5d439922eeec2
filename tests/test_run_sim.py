"""Whole runs on the simulator: recording round trip, crash recovery, analysis."""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.records import Message as McapMessage
from mcap.stream_reader import StreamReader
from typer.testing import CliRunner

from drivers.fri.emulate.lockstep import open_sim
from ffexp import loop
from ffexp.cli import app
from ffexp.errors import InputError
from ffexp.protocol import load_run_protocol, scene_path
from ffexp.recording import Recorder, load
from ffexp.recording.topics import CDR_TOPICS
from ffexp.runlog import RunLog

ROOT = Path(__file__).resolve().parents[1]
START_NS = 1_750_000_000 * 10**9


class CapturingRecorder(Recorder):
    """Keeps a copy of every CDR message the run log writes, as a numpy record."""

    def __init__(self, path: Path) -> None:
        super().__init__(path)
        self.captured: dict[str, list[tuple[int, np.ndarray]]] = {}

    def write_bytes(self, topic: str, time_ns: int, data: bytes) -> None:
        if topic in CDR_TOPICS:
            record = np.frombuffer(data, dtype=CDR_TOPICS[topic].spec.dtype)
            self.captured.setdefault(topic, []).append((time_ns, record))
        super().write_bytes(topic, time_ns, data)

    def write_batch(self, time_ns: int, messages: list[tuple[str, bytes]]) -> None:
        for topic, data in messages:
            if topic in CDR_TOPICS:
                record = np.frombuffer(data, dtype=CDR_TOPICS[topic].spec.dtype)
                self.captured.setdefault(topic, []).append((time_ns, record))
        super().write_batch(time_ns, messages)

    def write_series(self, topic: str, times_ns: list[int], datas: list[bytes]) -> None:
        dtype = CDR_TOPICS[topic].spec.dtype
        for t, data in zip(times_ns, datas, strict=True):
            self.captured.setdefault(topic, []).append((t, np.frombuffer(data, dtype=dtype)))
        super().write_series(topic, times_ns, datas)


def test_recording_round_trip_of_a_sim_run(tmp_path: Path) -> None:
    ppath = ROOT / "protocols/method1_case1.toml"
    protocol = load_run_protocol(ppath, ["run.timeout_s=1.5"])
    robot, sensor = open_sim(scene_path(ppath, protocol), seed=protocol.seed)
    path = tmp_path / "run.mcap"
    rec = CapturingRecorder(path)
    with rec:
        loop.run(protocol, robot, sensor, RunLog(rec, START_NS, protocol.run.tf_period_s))
    loaded = load(path)
    assert loaded.complete and not loaded.warnings
    assert {"/ft/raw", "/robot/state", "/robot/measurement", "/sim/truth"} <= set(rec.captured)
    for topic, items in rec.captured.items():
        data = loaded.topic(topic)
        assert data.log_time_ns.tolist() == [t for t, _ in items], topic
        records = np.concatenate([np.atleast_1d(r) for _, r in items])
        for name in data.fields:
            np.testing.assert_array_equal(data[name], records[name], err_msg=f"{topic}.{name}")
    assert len(loaded.topic("/robot/measurement")) == 1 + round(1.5 / 0.005) + round(0.1 / 0.005)
    # the intent beside what was applied: CONNECT keeps the robot's set-point (mirrored),
    # then the same Cartesian command as asked
    intent = loaded.topic("/control/command")
    given = intent["given"].astype(bool)
    assert not given[0] and given[-1]
    np.testing.assert_array_equal(intent["wrench"][given], intent["applied_wrench"][given])
    assert np.all(intent["status"][~given] == 1)  # HELD
    # in file order (every chunk, and chunk after chunk) messages are in log-time order
    with path.open("rb") as fh:
        times = [r.log_time for r in StreamReader(fh).records if isinstance(r, McapMessage)]
    assert len(times) > 1000 and times == sorted(times)


def _measurements_on_disk(path: Path, copy: Path) -> int:
    """Measurements a kill -9 now would leave in ``path`` (read from a copy; 0 while the
    file is not readable yet: created, nothing flushed)."""
    if not path.is_file():
        return 0
    shutil.copyfile(path, copy)
    try:
        rec = load(copy)
    except InputError:
        return 0
    return len(rec.topic("/robot/measurement")) if "/robot/measurement" in rec.topics else 0


@pytest.mark.slow
def test_kill_9_keeps_what_was_flushed_and_the_file_recovers(tmp_path: Path) -> None:
    """A run killed once its file holds more than 100 measurements: recover it and analyse
    it. (That a flush comes at least once a second of wall time, so a kill loses at most
    about a second, is tested with a given clock in test_recording.py.)"""
    out = tmp_path / "runs"
    proc = subprocess.Popen(
        [
            sys.executable, "-c", "from ffexp.cli import main; main()", "run",
            str(ROOT / "protocols/method3_impedance.toml"), "--out", str(out),
            # a run that does not end before the kill: a long timeout and an
            # alignment tolerance no contact meets
            "--set", "run.timeout_s=600", "--set", "alignment.lateral_tol_m=1e-9",
        ],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE,
    )
    # killed when the disk holds enough, not after a fixed wall time (on a loaded
    # machine 5 s did not even see the file created)
    try:
        deadline = time.monotonic() + 240
        seen = 0
        while seen <= 100:
            assert time.monotonic() < deadline and proc.poll() is None
            time.sleep(0.2)  # real-time: polls another process's progress
            files = list(out.glob("*.mcap"))
            assert len(files) <= 1
            seen = _measurements_on_disk(files[0], tmp_path / "seen.mcap") if files else 0
    finally:
        proc.kill()  # SIGKILL
        proc.wait()
    assert proc.returncode == -signal.SIGKILL
    files = list(out.glob("*.mcap"))
    assert len(files) == 1
    broken = files[0]
    fixed = tmp_path / "fixed.mcap"
    runner = CliRunner()
    result = runner.invoke(app, ["recover", str(broken), "-o", str(fixed)])
    assert result.exit_code == 0, result.stderr
    assert "unfinished file" in result.stdout
    rec = load(fixed)
    assert not rec.complete  # a valid file, but the run's end is not in it
    assert "the run's end is not recorded" in rec.warnings[0]
    seq = rec.topic("/robot/measurement")["seq"]
    assert len(seq) >= seen > 100  # what was on disk before the kill is kept
    assert np.all(np.diff(seq.astype(np.int64)) == 1)  # nothing missing before the cut
    result = runner.invoke(app, ["analyze", str(fixed), "--json"])
    assert result.exit_code == 0, result.stderr
    metrics = json.loads(result.stdout)
    assert metrics["protocol"] == "method3_impedance"
    assert metrics["complete"] is False and metrics["trial_valid"] is None
    assert metrics["duration_s"] > 0.5
    # analysing the unfinished file directly works too, with a warning
    result = runner.invoke(app, ["analyze", str(broken), "--json"])
    assert result.exit_code == 0
    assert "incomplete" in result.stderr


def test_the_recorded_library_versions_are_their_distributions_versions() -> None:
    """``_dist_versions`` reads a loaded module's ``__version__``: the same strings as
    ``importlib.metadata`` (what it read before); the revision started beside the
    set-up is ``source_revision``'s."""
    from importlib import metadata

    from ffexp import experiment
    from ffexp.revision import source_revision

    experiment._dist_versions.cache_clear()
    got = dict(experiment._dist_versions())
    assert got == {name: metadata.version(name) for name in got}
    source_revision.cache_clear()  # not known yet: git runs in a thread
    revision = experiment._revision_beside()
    assert revision is not source_revision
    assert revision() == source_revision()
    assert experiment._revision_beside() is source_revision  # known now: no thread
