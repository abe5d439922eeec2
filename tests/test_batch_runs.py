"""A sweep's runs made in a batch (ffexp.sweeps.batch) are the runs made alone.

One batch holds runs of different methods (Method I case I, II, III) and scenes
(the target's lateral offset and yaw, the funnel's friction set per run), one that
aborts (a workspace box it leaves), one whose protocol the run rejects, and one
that fails mid-run (an error raised by its world at a cycle: an exception that is
not the simulator's, so the run raises, as a bug in one scene would). Each run's
recording must equal the same run made alone, every numeric topic bit for bit,
and its row the row alone; the failing run ends alone with its error, the others
finish.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from drivers.world.gate import PhysicsGate
from drivers.world.world import SimWorld
from ffexp.diff import diff
from ffexp.recording import load
from ffexp.sweeps.batch import run_batch
from ffexp.sweeps.worker import RUN_FILE, RUNS_DIR, Job, run_one

ROOT = Path(__file__).resolve().parents[1]
SHORT = "run.timeout_s=1.5"
FAIL_SEED = 97
FAIL_CYCLE = 60


def jobs(out: Path) -> list[Job]:
    def job(rid: str, protocol: str, *overrides: str) -> Job:
        return Job(rid, str(ROOT / f"protocols/{protocol}.toml"), (SHORT, *overrides),
                   str(out), {"protocol": protocol})

    return [
        job("m1-near", "method1_case1", 'scene.set=["target.lateral=0.006"]'),
        job("m1-far", "method1_case1", 'scene.set=["target.lateral=0.014", "target.yaw_deg=-4.0"]'),
        job("m2", "method2", "seed=3"),
        job("m3", "method3_impedance", 'scene.set=["target.mu=0.009"]'),
        job("abort", "method1_case1", "limits.workspace_m=[0.05, 0.15, 0.01]"),
        job("rejected", "method2", "align.nope=1"),
        job("fails", "method3_impedance", f"seed={FAIL_SEED}"),
    ]


@pytest.fixture
def failing_world(monkeypatch: pytest.MonkeyPatch) -> None:
    """The world of the run seeded FAIL_SEED raises at cycle FAIL_CYCLE."""
    real = SimWorld.advance

    def advance(self: SimWorld, command: Any = None) -> None:
        if self.seed == FAIL_SEED and self.cycle == FAIL_CYCLE:
            raise ValueError(f"scene broke at cycle {self.cycle}")
        real(self, command)

    monkeypatch.setattr(SimWorld, "advance", advance)


def same_row(a: dict[str, Any], b: dict[str, Any]) -> bool:
    return {k: v for k, v in a.items() if k != "wall_s"} == \
        {k: v for k, v in b.items() if k != "wall_s"}


@pytest.mark.usefixtures("failing_world")
def test_runs_made_in_a_batch_are_the_runs_made_alone(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    widths: list[int] = []
    real = PhysicsGate._dispatch

    def dispatch(self: PhysicsGate, calls: list[Any]) -> None:
        widths.append(len(calls))
        real(self, calls)

    monkeypatch.setattr(PhysicsGate, "_dispatch", dispatch)
    batch = jobs(tmp_path / "batch")
    outcomes = run_batch(tuple(batch), threads=2)
    # the six runs that step were stepped together; the failing one and the aborting
    # one left first, the others went on (runs join as their worlds start stepping)
    assert max(widths) == 6 and widths[-1] == 4
    monkeypatch.setattr(PhysicsGate, "_dispatch", real)
    assert [kind for kind, _ in outcomes] == ["row"] * len(batch)
    rows = {job.run_id: row for job, (_, row) in zip(batch, outcomes, strict=True)}
    for job in jobs(tmp_path / "alone"):
        ref = run_one(job)
        got = rows[job.run_id]
        assert same_row(got, ref), job.run_id
        # the row is committed where run_one commits it
        committed = json.loads((tmp_path / "batch" / RUNS_DIR / job.run_id / "row.json")
                               .read_text())
        assert same_row(committed, got)
        if ref["error"] is not None:
            continue
        a = load(tmp_path / "batch" / RUNS_DIR / job.run_id / RUN_FILE)
        b = load(tmp_path / "alone" / RUNS_DIR / job.run_id / RUN_FILE)
        result = diff(a, b, rtol=0.0, atol=0.0)
        assert result.ok and not result.only_a and not result.only_b, job.run_id
        assert len(result.topics) >= 10 and all(t.paired > 0 for t in result.topics)
        assert all(t.max_abs == 0.0 for t in result.topics)
    # what each special run became, in the batch as alone
    assert rows["abort"]["aborted"] and "workspace" in rows["abort"]["aborted"]
    assert rows["abort"]["duration_s"] < 1.5
    assert "align.nope" in rows["rejected"]["error"] and rows["rejected"]["path"] is None
    assert rows["fails"]["error"] == f"ValueError: scene broke at cycle {FAIL_CYCLE}"
    for rid in ("m1-near", "m1-far", "m2", "m3"):
        assert rows[rid]["error"] is None and rows[rid]["aborted"] is None
        assert rows[rid]["duration_s"] >= 1.5  # ran to its timeout after the failure
    # the scenes differ: the runs are not copies of one another
    assert rows["m1-near"]["final_lateral_error_m"] != rows["m1-far"]["final_lateral_error_m"]
