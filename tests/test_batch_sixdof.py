"""6-DOF runs made in a batch (ffexp.sweeps.batch) are the runs made alone.

Two short ``sixdof_method1`` runs (RK4, the free zero-g target) whose scenes differ
(the target's lateral offset, pitch and drift) are stepped together in one batch,
then each alone: every numeric topic of each recording must be the same bits
(``ffexp.diff`` with no tolerance), and the two runs must differ from each other.
"""

from __future__ import annotations

from pathlib import Path

from drivers.world.gate import PhysicsGate
from ffexp.diff import diff
from ffexp.recording import load
from ffexp.sweeps.batch import run_batch
from ffexp.sweeps.worker import RUN_FILE, RUNS_DIR, Job, run_one

ROOT = Path(__file__).resolve().parents[1]
PROTOCOL = str(ROOT / "protocols/sixdof_method1.toml")
SHORT = "run.timeout_s=1.2"
SCENES = {
    "near": 'scene.set=["target.lateral=0.004", "target.pitch_deg=1.5"]',
    "drifting": 'scene.set=["target.lateral=0.010", "target.drift_mps=[0.0, 0.002, 0.0]"]',
}


def jobs(out: Path) -> list[Job]:
    return [Job(rid, PROTOCOL, (SHORT, scene), str(out), {"scene": rid})
            for rid, scene in SCENES.items()]


def test_sixdof_runs_in_a_batch_equal_the_runs_alone(tmp_path: Path) -> None:
    gate = PhysicsGate()
    outcomes = run_batch(tuple(jobs(tmp_path / "batch")), gate=gate)
    assert [kind for kind, _ in outcomes] == ["row", "row"]
    assert all(row["error"] is None for _, row in outcomes), outcomes
    assert gate.stats.widths.get(2, 0) > 100  # the two stepped together, cycle by cycle
    for job in jobs(tmp_path / "alone"):
        assert run_one(job)["error"] is None
    rec = {(where, rid): load(tmp_path / where / RUNS_DIR / rid / RUN_FILE)
           for where in ("batch", "alone") for rid in SCENES}
    for rid in SCENES:
        result = diff(rec["batch", rid], rec["alone", rid], rtol=0.0, atol=0.0)
        assert result.ok and not result.only_a and not result.only_b, rid
        assert len(result.topics) >= 10
        assert all(t.paired > 0 and t.n_a == t.n_b == t.paired for t in result.topics)
        assert all(t.max_abs == 0.0 for t in result.topics), rid
    # the scenes differ, so the runs do: not one run compared with itself
    other = diff(rec["batch", "near"], rec["batch", "drifting"], rtol=0.0, atol=0.0)
    assert not other.ok
