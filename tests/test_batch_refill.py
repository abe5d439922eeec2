"""``local:W,batch:N`` refills: a batch process keeps N runs live, a queued job joins
its running batch as a run ends, and each run's row comes back as the run ends.

The executor's scheduling is tested on a thread pool with a stand-in for ``run_one``
that steps a small MuJoCo model through the batch's gate for as many cycles as its
job says (so runs of different lengths end at different cycles of one batch); a
process that dies mid-batch on the real process pool.
"""

from __future__ import annotations

import os
import signal
import threading
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

import mujoco
import pytest

from drivers.world.gate import current_gate
from ffexp.sweeps import batch as batch_mod
from ffexp.sweeps import engine
from ffexp.sweeps.batch import RefillExecutor
from ffexp.sweeps.executors import make_executor, parse_executor
from ffexp.sweeps.worker import RUNS_DIR, Job, run_one

ROOT = Path(__file__).resolve().parents[1]
XML = """<mujoco><option gravity="0 0 0"/><worldbody><body><joint type="slide"/>
<geom size="0.1" mass="1"/></body></worldbody></mujoco>"""


class Stepping:
    """A stand-in for run_one: ``cycles`` cycles of its own model through the gate;
    its row says where it ran (the thread), the cycle of the batch it joined at and
    how many runs were live beside it."""

    def __init__(self) -> None:
        self.go = threading.Event()  # the runs step once every job was submitted
        self.go.set()
        self.lock = threading.Lock()
        self.live: dict[int, int] = {}  # runs live per thread
        self.widest = 0

    def __call__(self, job: Job) -> dict[str, Any]:
        gate = current_gate()
        assert gate is not None  # a run of a batch
        me = threading.get_ident()
        with self.lock:
            self.live[me] = self.live.get(me, 0) + 1
            self.widest = max(self.widest, self.live[me])
        self.go.wait(30)
        joined = gate.stats.dispatches
        m = mujoco.MjModel.from_xml_string(XML)
        d = mujoco.MjData(m)
        d.qvel[0] = 1.0
        try:
            for _ in range(job.columns["cycles"]):
                gate.step(m, d, 1)
        finally:
            with self.lock:
                self.live[me] -= 1
        return {"run_id": job.run_id, **job.columns, "error": None, "wall_s": 0.0,
                "path": None, "thread": me, "joined": joined, "qpos": float(d.qpos[0])}


def jobs_of(cycles: list[int], out: Path) -> list[Job]:
    return [Job(f"j{i}", "p.toml", (), str(out), {"cycles": n}) for i, n in enumerate(cycles)]


def test_a_run_that_ends_frees_its_slot_for_a_queued_job(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    fake = Stepping()
    fake.go.clear()  # (a process's first run holds it until all jobs are in its pipe)
    monkeypatch.setattr(batch_mod, "run_one", fake)
    ex = RefillExecutor(ThreadPoolExecutor(2), processes=2, batch=3)  # type: ignore[arg-type]
    cycles = [300, 5, 10, 300, 15, 20, 25, 30, 35, 40]
    ended: list[str] = []
    futs = [ex.submit(run_one, j) for j in jobs_of(cycles, tmp_path)]
    fake.go.set()
    for f in futs:
        f.add_done_callback(lambda f: ended.append(f.result()["run_id"]))
    rows = [f.result(timeout=60) for f in futs]
    ex.shutdown()
    # every run ran its own cycles (a run stepped with another's model or twice would not)
    step = mujoco.MjModel.from_xml_string(XML).opt.timestep
    assert [r["qpos"] for r in rows] == pytest.approx([n * step for n in cycles])
    # never more than 3 live in a process, both processes used
    assert fake.widest == 3 and len({r["thread"] for r in rows}) == 2
    # the short runs' slots were taken by queued jobs while the long ones ran
    assert sum(r["joined"] > 0 for r in rows) >= len(cycles) - 6
    # each row came back when its run ended, not with its batch: in a process, a run
    # that ended at an earlier cycle of its batch was resolved first
    end = {r["run_id"]: (r["thread"], r["joined"] + r["cycles"]) for r in rows}
    for a in end:
        for b in end:
            if end[a][0] == end[b][0] and end[a][1] < end[b][1]:
                assert ended.index(a) < ended.index(b), (a, b)
    assert end["j2"][0] == end["j0"][0] and ended.index("j2") < ended.index("j0")


def test_a_stop_cancels_the_queued_jobs_and_the_running_finish(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(batch_mod, "run_one", Stepping())
    ex = RefillExecutor(ThreadPoolExecutor(1), processes=1, batch=2)  # type: ignore[arg-type]
    stop = {"now": False}

    def on_change(c: engine.Counts) -> None:
        if c.done >= 1:
            stop["now"] = True  # as a Ctrl-C after the first run ended

    with engine.Runner(tmp_path, ex, 2, on_change=on_change,
                       stop_requested=lambda: stop["now"]) as r:
        with pytest.raises(engine.Stopped):
            r.run_batch(jobs_of([3, 300, 300, 300, 300], tmp_path))
    ex.shutdown()
    # the first ended; the one running beside it finished; the queued never started
    # (the freed slot was not refilled once the stop was asked)
    assert (r.counts.done, r.counts.failed) == (2, 0)
    assert r.counts.total == 2


def test_a_slot_freed_by_a_run_is_not_refilled_before_its_row_is_resolved(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # The race the test above could lose on a loaded machine, made certain: another
    # thread dispatches (as the engine's submit does, holding the engine's lock that the
    # first run's callback waits for) after the collector read the first run's row and
    # before it resolved the run's future, whose callback asks the stop. The slot is not
    # free yet: nothing queued may go.
    monkeypatch.setattr(batch_mod, "run_one", Stepping())
    ex = RefillExecutor(ThreadPoolExecutor(1), processes=1, batch=2)  # type: ignore[arg-type]
    read = ex._read
    queued: list[tuple[int, int]] = []

    def read_then_dispatch(s: Any) -> list[Any]:
        out = read(s)
        if out:
            with ex._cond:
                before = len(ex._pending)
                ex._dispatch()  # another thread's dispatch in between
                queued.append((before, len(ex._pending)))
        return out

    monkeypatch.setattr(ex, "_read", read_then_dispatch)
    stop = {"now": False}

    def on_change(c: engine.Counts) -> None:
        if c.done >= 1:
            stop["now"] = True

    with engine.Runner(tmp_path, ex, 2, on_change=on_change,
                       stop_requested=lambda: stop["now"]) as r:
        with pytest.raises(engine.Stopped):
            r.run_batch(jobs_of([3, 300, 300, 300, 300], tmp_path))
    ex.shutdown()
    assert queued and all(before == after for before, after in queued), queued
    assert (r.counts.done, r.counts.failed, r.counts.total) == (2, 0, 2)


def test_other_work_and_shutdown(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(batch_mod, "run_one", Stepping())
    ex = RefillExecutor(ThreadPoolExecutor(1), processes=1, batch=2)  # type: ignore[arg-type]
    assert ex.submit(sum, [1, 2]).result() == 3  # not run_one: to the pool as it is
    futs: list[Future[dict[str, Any]]] = [ex.submit(run_one, j)
                                          for j in jobs_of([50, 50, 50], tmp_path)]
    ex.shutdown(wait=True)  # the jobs submitted run first
    assert [f.result()["run_id"] for f in futs] == ["j0", "j1", "j2"]
    with pytest.raises(RuntimeError, match="shutdown"):
        ex.submit(run_one, jobs_of([1], tmp_path)[0])


@pytest.mark.slow
def test_a_batch_process_that_dies_fails_its_runs_uncommitted(tmp_path: Path) -> None:
    ex, slots = make_executor(parse_executor("local:1,batch:2"))
    protocol = str(ROOT / "protocols/method1_case1.toml")
    jobs = [Job(f"r{i}", protocol, (f"run.timeout_s={s}",), str(tmp_path), {})
            for i, s in enumerate([0.2, 30.0, 30.0, 30.0])]

    def kill(f: Future[Any]) -> None:  # the first run ended: its process dies now
        for pid in list(getattr(ex, "_processes", None) or {}):
            os.kill(pid, signal.SIGKILL)

    with engine.Runner(tmp_path, ex, slots) as r:
        first = ex.submit(run_one, jobs[0])
        first.add_done_callback(kill)
        rows = r.run_batch(jobs[1:])
        assert first.result()["error"] is None  # committed before the process died
    ex.shutdown()
    # the runs live in it (one joined as the first ended) and the one queued are rows of
    # a failed worker, none committed: a later sweep runs them again
    assert all(row["error"].startswith("worker failed: BrokenProcessPool") for row in rows)
    done = [p.name for p in (tmp_path / RUNS_DIR).iterdir() if not p.name.startswith(".tmp-")]
    assert done == ["r0"]
