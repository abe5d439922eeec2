"""Files that tell the truth: a recording without its run's end (a run killed with
SIGKILL, then ``ffexp recover``; a finished file cut in half) is ``complete: no`` and
its trial's validity is unknown in ``analyze``, ``compare``, ``export`` and the
metrics the report reads; a whole run's file stays complete and valid."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from ffexp.analysis import compare_row, metrics
from ffexp.cli import app
from ffexp.experiment import RigChoice, run_file
from ffexp.linkcheck import UNKNOWN
from ffexp.recording import load

ROOT = Path(__file__).resolve().parents[1]
PROTOCOL = ROOT / "protocols/method1_case1.toml"
DEADLINE_S = 240.0


@pytest.fixture(scope="module")
def whole(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished simulated run (about 2.8 MB: a few 1 MB chunks)."""
    out = tmp_path_factory.mktemp("whole")
    return run_file(PROTOCOL, ["run.timeout_s=10"], rig=RigChoice(driver="sim"),
                    out_dir=out).path


def _analyze(path: Path) -> dict[str, Any]:
    result = CliRunner().invoke(app, ["analyze", "--json", str(path)])
    assert result.exit_code == 0, result.output
    return json.loads(next(x for x in result.stdout.splitlines() if x.startswith("{")))


def _compare(path: Path) -> dict[str, Any]:
    result = CliRunner().invoke(app, ["compare", "--json", str(path)])
    assert result.exit_code == 0, result.output
    return json.loads(next(x for x in result.stdout.splitlines() if x.startswith("{")))


def _export_summary(path: Path, out: Path) -> dict[str, Any]:
    result = CliRunner().invoke(app, ["export", str(path), "--format", "csv", "--topic",
                                      "/estimator/state", "--out", str(out)])
    assert result.exit_code == 0, result.output
    summary: dict[str, Any] = json.loads((out / "recording.json").read_text())
    return summary


def _assert_untrue(path: Path, tmp_path: Path) -> None:
    rec = load(path)
    assert not rec.complete
    m = metrics(rec)  # what the report reads
    assert (m.complete, m.trial_valid, m.trial_validity) == (False, None, UNKNOWN)
    assert compare_row(rec, m)["end"] == "cut"
    for row in (_analyze(path), _compare(path), _export_summary(path, tmp_path / "tables")):
        assert row["complete"] is False
        assert row["trial_valid"] is None and row["trial_validity"] == UNKNOWN


def test_a_whole_run_is_complete_and_its_trial_valid(whole: Path, tmp_path: Path) -> None:
    for row in (_analyze(whole), _compare(whole), _export_summary(whole, tmp_path / "t")):
        assert row["complete"] is True
        assert row["trial_valid"] is True and row["trial_validity"] == "valid"


@pytest.mark.slow
def test_a_file_cut_in_half_and_its_recovery_are_incomplete(whole: Path,
                                                             tmp_path: Path) -> None:
    data = whole.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    _assert_untrue(cut, tmp_path / "a")
    warnings = load(cut).warnings
    assert re.search(r"up to \d+\.\d{3} s of the run", warnings[0]), warnings  # not ns epochs
    recovered = tmp_path / "cut.recovered.mcap"
    result = CliRunner().invoke(app, ["recover", str(cut), "-o", str(recovered)])
    assert result.exit_code == 0 and "complete: no" in result.stdout, result.output
    _assert_untrue(recovered, tmp_path / "b")


@pytest.mark.slow
def test_a_run_killed_with_sigkill_then_recovered_is_incomplete(tmp_path: Path) -> None:
    proc = subprocess.Popen(
        [sys.executable, "-m", "ffexp", "run", str(PROTOCOL), "--set", "run.timeout_s=120",
         "--set", "approach.speed_mps=0.002",  # no contact, no end for minutes
         "--out", str(tmp_path / "runs")],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)})
    try:
        assert proc.stderr is not None
        for line in proc.stderr:  # a state line every 5 s of run time (no terminal)
            m = re.search(r" (\d+\.\d) s ", line)
            if m and float(m.group(1)) >= 10.0:  # a few 1 MB chunks are on disk
                break
        else:
            raise AssertionError("the run ended before it could be killed")
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(DEADLINE_S)
    killed = next((tmp_path / "runs").glob("*.mcap"))
    recovered = tmp_path / "killed.recovered.mcap"
    result = CliRunner().invoke(app, ["recover", str(killed), "-o", str(recovered)])
    assert result.exit_code == 0, result.output
    _assert_untrue(recovered, tmp_path / "t")
