"""``--executor batch:N``: the sweep engine's runs in batches stepped together.

The executor's grouping and stopping are tested with a thread pool and a counting
batch function in this process; the rows, caching by run id and restart after a
stop on the real process pool against ``local`` (the same rows); the option's bad
input as the other executors'.
"""

from __future__ import annotations

import json
import threading
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from ffexp.cli import app
from ffexp.errors import ConfigError
from ffexp.sweeps import batch as batch_mod
from ffexp.sweeps import engine, table
from ffexp.sweeps.batch import BatchExecutor
from ffexp.sweeps.executors import available_cpus, make_executor, parse_executor
from ffexp.sweeps.grid import execute, prepare
from ffexp.sweeps.worker import RUNS_DIR, Job, run_one

ROOT = Path(__file__).resolve().parents[1]
P1 = ROOT / "protocols/method1_case1.toml"
SHORT = "run.timeout_s=0.4"
cli = CliRunner()


def test_parse_batch_executor() -> None:
    spec = parse_executor("local:2,batch:3")
    assert (spec.kind, spec.processes, spec.batch, spec.workers) == ("batch", 2, 3, 6)
    assert spec.label == "local:2,batch:3"
    cpus = available_cpus()
    for text in ("batch:4", "local,batch:4"):
        spec = parse_executor(text)
        assert (spec.processes, spec.batch, spec.workers) == (cpus, 4, 4 * cpus)
    for bad in ("batch", "batch:0", "batch:x", "local:0,batch:2", "local:2,batch",
                "ray:x,batch:2", "rays,batch:2", "local:2,batch:2,x", "batch:2,local:2"):
        with pytest.raises(ConfigError, match="--executor"):
            parse_executor(bad)


def fake_jobs(n: int, out: Path) -> list[Job]:
    return [Job(f"j{i}", "p.toml", (), str(out), {"i": i}) for i in range(n)]


class Recorded:
    """A stand-in for run_batch: the batches it was given, rows made of the jobs."""

    def __init__(self, fail: str = "") -> None:
        self.batches: list[list[str]] = []
        self.fail = fail
        self.lock = threading.Lock()
        self.release = threading.Event()
        self.release.set()

    def __call__(self, jobs: tuple[Job, ...], threads: int = 1) -> list[Any]:
        self.release.wait(10)
        with self.lock:
            self.batches.append([j.run_id for j in jobs])
        return [("failed", "KeyboardInterrupt: ") if j.run_id == self.fail else
                ("row", {"run_id": j.run_id, **j.columns, "error": None, "wall_s": 0.0,
                         "path": None}) for j in jobs]


def test_jobs_are_grouped_into_batches_over_the_free_processes(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    rec = Recorded()
    rec.release.clear()  # the batches hold their process until released
    monkeypatch.setattr(batch_mod, "run_batch", rec)
    ex = BatchExecutor(ThreadPoolExecutor(2), processes=2, batch=4)  # type: ignore[arg-type]
    jobs = fake_jobs(14, tmp_path)
    futs = [ex.submit(run_one, j) for j in jobs[:11]]
    # two full batches went as they came; the rest waits for a free process
    assert [f.running() for f in futs] == [True] * 8 + [False] * 3
    ex.flush()
    assert not futs[8].running()
    rec.release.set()
    assert [f.result()["run_id"] for f in futs] == [j.run_id for j in jobs[:11]]
    assert sorted(len(b) for b in rec.batches) == [3, 4, 4]
    assert sorted(r for b in rec.batches for r in b) == sorted(j.run_id for j in jobs[:11])
    rec.batches.clear()
    # a few jobs use every process: 3 jobs on 2 free processes are batches of 2 and 1
    futs = [ex.submit(run_one, j) for j in jobs[11:]]
    ex.flush()
    assert [f.result()["i"] for f in futs] == [11, 12, 13]
    assert sorted(len(b) for b in rec.batches) == [1, 2]
    ex.shutdown()
    # through the engine: the rows in order, each job once
    rec.batches.clear()
    ex = BatchExecutor(ThreadPoolExecutor(2), processes=2, batch=3)  # type: ignore[arg-type]
    with engine.Runner(tmp_path, ex, 6) as r:
        rows = r.run_batch(jobs)
    ex.shutdown()
    assert [row["run_id"] for row in rows] == [j.run_id for j in jobs]
    assert sorted(r for b in rec.batches for r in b) == sorted(j.run_id for j in jobs)
    assert max(len(b) for b in rec.batches) == 3
    # something other than run_one goes to the pool as it is
    ex = BatchExecutor(ThreadPoolExecutor(1), processes=1, batch=4)  # type: ignore[arg-type]
    assert ex.submit(sum, [1, 2]).result() == 3
    ex.shutdown()
    with pytest.raises(RuntimeError, match="shutdown"):
        ex.submit(run_one, jobs[0])


def test_a_stop_cancels_the_jobs_not_yet_in_a_batch(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    rec = Recorded(fail="j1")
    rec.release.clear()
    monkeypatch.setattr(batch_mod, "run_batch", rec)
    ex = BatchExecutor(ThreadPoolExecutor(1), processes=1, batch=2)  # type: ignore[arg-type]
    futs: list[Future[dict[str, Any]]] = [ex.submit(run_one, j)
                                          for j in fake_jobs(5, tmp_path)]
    ex.flush()
    assert [f.running() for f in futs] == [True, True, False, False, False]
    assert all(f.cancel() for f in futs[2:4])  # queued: cancelled, as the engine does
    rec.release.set()
    assert futs[0].result()["run_id"] == "j0"
    with pytest.raises(RuntimeError, match="KeyboardInterrupt"):  # a run's thread failed
        futs[1].result()
    assert futs[4].result()["run_id"] == "j4"  # the rest went on in the next batch
    ex.shutdown()
    assert rec.batches == [["j0", "j1"], ["j4"]]


def _runner(out: Path, text: str, **kw: Any) -> engine.Runner:
    ex, slots = make_executor(parse_executor(text))
    return engine.Runner(out, ex, slots, **kw)


@pytest.mark.slow
def test_batch_executor_gives_the_rows_of_local_and_restarts(tmp_path: Path) -> None:
    prep = prepare(P1, vary=["align.k_ri[3]=0.25,0.5", "scene.target.lateral=0.010,0.014"],
                   fixed=[SHORT])
    with _runner(tmp_path / "local", "local:2") as r:
        local = execute(prep, r, figures=False)["rows"]
        r.executor.shutdown()
    stop = {"now": False}

    def on_change(c: engine.Counts) -> None:
        if c.done >= 2:
            stop["now"] = True

    out = tmp_path / "batch"
    with _runner(out, "local:1,batch:2", on_change=on_change,
                 stop_requested=lambda: stop["now"]) as r:
        with pytest.raises(engine.Stopped):
            execute(prep, r, figures=False)
        r.executor.shutdown()
    first = {p.name: (p / "row.json").stat().st_mtime_ns for p in (out / RUNS_DIR).iterdir()}
    assert 2 <= len(first) < 4  # the running batch finished; the rest was not started
    with _runner(out, "local:1,batch:2") as r:
        rows = execute(prep, r, figures=False)["rows"]
        assert r.counts.skipped == len(first)
        again = r.run_batch(prep.jobs(out))  # everything is done: nothing runs
        assert r.counts.skipped == len(first) + 4
        r.executor.shutdown()
    for name, mtime in first.items():
        assert (out / RUNS_DIR / name / "row.json").stat().st_mtime_ns == mtime
    assert table.without_wall_time(rows) == table.without_wall_time(local)
    assert table.without_wall_time(again) == table.without_wall_time(rows)
    assert all(row["error"] is None for row in rows)


@pytest.mark.slow
def test_cli_sweep_on_batches(tmp_path: Path) -> None:
    out = tmp_path / "s"
    res = cli.invoke(app, ["sweep", str(P1), "--vary", "align.k_ri[3]=0.25,0.5,0.75",
                           "--set", SHORT, "--executor", "local:1,batch:3", "--out", str(out),
                           "--json", "--no-figures"])
    assert res.exit_code == 0, res.output
    lines = [json.loads(x) for x in res.stdout.splitlines() if x.startswith("{")]
    assert len(lines) == 3 and all(x["error"] is None for x in lines)
    assert len(list((out / RUNS_DIR).glob("*/run.mcap"))) == 3


@pytest.mark.parametrize("bad", ["batch:0", "local:2,batch:x"])
def test_bad_batch_executor_is_one_line_exit_2(tmp_path: Path, bad: str) -> None:
    res = cli.invoke(app, ["sweep", str(P1), "--vary", "align.k_ri[3]=0.5", "--executor", bad,
                           "--out", str(tmp_path / "never")])
    assert res.exit_code == 2
    err = [x for x in res.output.splitlines() if x.strip()]
    assert len(err) == 1 and err[0].startswith("error: ") and bad in err[0], res.output
    assert not (tmp_path / "never").exists()


class BrokenPool:
    """A pool whose first batch dies with its process, and which then refuses work."""

    def __init__(self) -> None:
        self.broken = False

    def submit(self, fn: Any, *args: Any) -> Future[Any]:
        from concurrent.futures.process import BrokenProcessPool

        if self.broken:
            raise BrokenProcessPool("a process of the pool died")
        self.broken = True
        fut: Future[Any] = Future()
        fut.set_exception(BrokenProcessPool("a process of the pool died"))
        return fut

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        pass


def test_a_dead_batch_process_fails_its_runs_uncommitted(tmp_path: Path) -> None:
    ex = BatchExecutor(BrokenPool(), processes=1, batch=2)  # type: ignore[arg-type]
    with engine.Runner(tmp_path, ex, 2) as r:
        rows = r.run_batch(fake_jobs(5, tmp_path))
    ex.shutdown()
    # every run is a row of a failed worker (as a broken pool's), none committed: a
    # later sweep runs them all
    assert [row["run_id"] for row in rows] == [f"j{i}" for i in range(5)]
    assert all(row["error"].startswith("worker failed: BrokenProcessPool") for row in rows)
    assert r.counts.failed == 5
    assert not list((tmp_path / RUNS_DIR).iterdir())
