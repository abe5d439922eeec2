"""A sweep killed half-way (SIGKILL to its process group: the sweep and its workers) and
started again finishes with every row once; the runs finished before the kill are kept
as they were (not run again), the half-written ones do not count."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from ffexp.sweeps.worker import RUNS_DIR, TMP_PREFIX

ROOT = Path(__file__).resolve().parents[1]
P1 = ROOT / "protocols/method1_case1.toml"
#: Longer runs than elsewhere, so that the kill lands while runs are in flight.
ARGS = ["--vary", "align.k_ri[3]=0.25,0.5", "--vary", "scene.target.lateral=0.010,0.012,0.014",
        "--seeds", "2", "--set", "run.timeout_s=1.0", "--executor", "local:2", "--no-figures"]
DEADLINE_S = 240.0


def _done(out: Path) -> list[Path]:
    runs = out / RUNS_DIR
    if not runs.is_dir():
        return []
    return [p for p in runs.iterdir() if not p.name.startswith(TMP_PREFIX)
            and (p / "row.json").is_file()]


@pytest.mark.slow
def test_killed_and_restarted_sweep_has_every_row_once(tmp_path: Path) -> None:
    out = tmp_path / "s"
    cmd = [sys.executable, "-m", "ffexp", "sweep", str(P1), *ARGS, "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    try:
        t0 = time.monotonic()
        while len(_done(out)) < 3 and proc.poll() is None:  # wait for a few finished runs
            assert time.monotonic() - t0 < DEADLINE_S, "the sweep made no progress"
            time.sleep(0.05)  # real-time: polls another process's progress
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    before = {p.name: (p / "row.json").stat().st_mtime_ns for p in _done(out)}
    assert 3 <= len(before) < 12, "kill the sweep half-way"
    res = subprocess.run([*cmd, "--json"], capture_output=True, text=True, timeout=DEADLINE_S)
    assert res.returncode == 0, res.stderr
    rows = [json.loads(x) for x in res.stdout.splitlines() if x.startswith("{")]
    assert len(rows) == 12 and len({r["run_id"] for r in rows}) == 12
    df = pd.read_parquet(out / "results.parquet")
    assert len(df) == 12 and df["run_id"].is_unique
    assert sorted(p.name for p in _done(out)) == sorted(df["run_id"])
    assert not list((out / RUNS_DIR).glob(f"{TMP_PREFIX}*"))
    for name, mtime in before.items():
        assert (out / RUNS_DIR / name / "row.json").stat().st_mtime_ns == mtime
    assert all(r["error"] is None for r in rows)


@pytest.mark.slow
def test_interrupted_sweep_exits_130_keeps_its_runs_and_goes_on(tmp_path: Path) -> None:
    """Ctrl-C (SIGINT): no new runs, the started ones finish and are kept, exit 130; the
    same command again completes the sweep without running them again."""
    out = tmp_path / "s"
    cmd = [sys.executable, "-m", "ffexp", "sweep", str(P1), *ARGS, "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    t0 = time.monotonic()
    while len(_done(out)) < 2 and proc.poll() is None:
        assert time.monotonic() - t0 < DEADLINE_S, "the sweep made no progress"
        time.sleep(0.05)  # real-time: polls another process's progress
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=DEADLINE_S)
    assert proc.returncode == 130, err
    assert "stopped; finished runs are kept" in err
    assert not list((out / RUNS_DIR).glob(f"{TMP_PREFIX}*"))  # the started runs finished
    before = {p.name: (p / "row.json").stat().st_mtime_ns for p in _done(out)}
    assert 2 <= len(before) < 12
    res = subprocess.run([*cmd, "--json"], capture_output=True, text=True, timeout=DEADLINE_S)
    assert res.returncode == 0, res.stderr
    assert len([x for x in res.stdout.splitlines() if x.startswith("{")]) == 12
    for name, mtime in before.items():
        assert (out / RUNS_DIR / name / "row.json").stat().st_mtime_ns == mtime
