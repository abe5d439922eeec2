"""Throughput of a sweep of short runs: one after another in one process (the bare
baseline) against the sweep engine on 1 and N local workers and on Ray, in the same run.

    python benchmarks/bench_sweep.py [--runs R] [--seconds S] [--workers N] [--repeats K]
                                     [--no-ray]

Every configuration runs the same R jobs (Method I case I, ``run.timeout_s=S``,
one seed each) into a fresh directory (nothing cached):

* baseline: :func:`ffexp.sweeps.worker.run_one` called R times in this process
  (run, analyse, commit: exactly a worker's work, no executor; imports done
  before the timing, as a warmed worker's are);
* ``local:1`` and ``local:N``: the engine on a process pool; its start-up (the
  spawn of N workers that import the simulator, a one-time cost per sweep) is
  timed apart and printed, the wall time is the runs' (steady throughput);
* ``ray:local``: the engine on a Ray instance started once before the repeats
  (Ray's own start, about 10 s, is printed separately, not counted).

A bare parallel baseline is measured in every repeat too: the same runs split
over N plain processes forked from the warmed benchmark process (no executor,
no queue): the speed-up this machine gives right now, whatever else runs on
it; the engine's speed-up is also printed as a fraction of it.

Repeats are interleaved (baseline, local:1, local:N, ray, baseline, ...) so
that a change of machine load hits all alike. Prints medians: wall time,
runs per second, speed-up over the baseline and speed-up per worker, and the
load average before and after.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from collections.abc import Callable
from concurrent.futures import Executor
from pathlib import Path
from typing import Any

from ffexp.sweeps import engine
from ffexp.sweeps.executors import available_cpus, make_executor, parse_executor
from ffexp.sweeps.grid import prepare
from ffexp.sweeps.worker import Job, run_one

ROOT = Path(__file__).resolve().parent.parent
PROTOCOL = ROOT / "protocols/method1_case1.toml"


def jobs_for(out: Path, runs: int, seconds: float) -> list[Job]:
    prep = prepare(PROTOCOL, seeds=runs, fixed=[f"run.timeout_s={seconds}"])
    return prep.jobs(out)


def baseline(out: Path, runs: int, seconds: float) -> float:
    jobs = jobs_for(out, runs, seconds)
    t0 = time.perf_counter()
    for job in jobs:
        row = run_one(job)
        assert row["error"] is None, row["error"]
    return time.perf_counter() - t0


def warm_worker() -> int:
    """Import what a run imports (a worker's one-time cost), then hold the worker a
    moment so that the next warm-up task goes to another one."""
    import importlib

    from ffexp.sweeps.executors import PRELOAD

    for name in PRELOAD:
        importlib.import_module(name)

    time.sleep(0.2)
    return os.getpid()


def _share(jobs: list[Job]) -> None:
    for job in jobs:
        run_one(job)


def bare_parallel(workers: int) -> Callable[[Path, int, float], float]:
    """The same runs split over ``workers`` plain processes forked from this (warmed)
    one, no executor, no queue: what the machine gives in parallel right now."""
    import multiprocessing

    def run(out: Path, runs: int, seconds: float) -> float:
        jobs = jobs_for(out, runs, seconds)
        ctx = multiprocessing.get_context("fork")
        procs = [ctx.Process(target=_share, args=(jobs[i::workers],)) for i in range(workers)]
        t0 = time.perf_counter()
        for p in procs:
            p.start()
        for p in procs:
            p.join()
        wall = time.perf_counter() - t0
        assert all(p.exitcode == 0 for p in procs)
        return wall
    return run


#: Start-up times of the executors (s), per configuration.
STARTUP: dict[str, list[float]] = {}


def on_engine(name: str, make: Callable[[], tuple[Executor, int]], keep: bool
              ) -> Callable[[Path, int, float], float]:
    """The engine's throughput: the executor is started and its workers warmed (timed
    apart, in STARTUP), then the runs are timed."""
    def run(out: Path, runs: int, seconds: float) -> float:
        jobs = jobs_for(out, runs, seconds)
        t0 = time.perf_counter()
        ex, slots = make()
        if not keep:
            for f in [ex.submit(warm_worker) for _ in range(2 * slots)]:
                f.result()
        STARTUP.setdefault(name, []).append(time.perf_counter() - t0)
        try:
            t1 = time.perf_counter()
            with engine.Runner(out, ex, slots) as r:
                rows = r.run_batch(jobs)
            wall = time.perf_counter() - t1
        finally:
            if not keep:
                ex.shutdown(wait=True)
        assert all(row["error"] is None for row in rows)
        return wall
    return run


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=12)
    ap.add_argument("--seconds", type=float, default=2.0, help="run.timeout_s of each run")
    ap.add_argument("--workers", type=int, default=available_cpus())
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--no-ray", action="store_true")
    args = ap.parse_args()
    warm_worker()  # the baseline's process imports what a run needs before it is timed
    load0 = os.getloadavg()
    configs: dict[str, tuple[Callable[[Path, int, float], float], int]] = {
        "one process (baseline)": (baseline, 1),
        f"{args.workers} bare processes": (bare_parallel(args.workers), args.workers),
        "local:1": (on_engine("local:1", lambda: make_executor(parse_executor("local:1")),
                              False), 1),
        f"local:{args.workers}": (on_engine(
            f"local:{args.workers}",
            lambda: make_executor(parse_executor(f"local:{args.workers}")), False),
            args.workers),
    }
    ray_mod: Any = None
    if not args.no_ray:
        try:
            import ray as ray_mod
        except ImportError:
            print("ray not installed: skipping ray:local")
    if ray_mod is not None:
        from ffexp.sweeps.executors import RayExecutor

        t0 = time.perf_counter()
        ray_mod.init(num_cpus=args.workers, include_dashboard=False, log_to_driver=False)
        ray_ex = RayExecutor.connect("auto")
        print(f"ray start: {time.perf_counter() - t0:.1f} s (not counted)")
        name = f"ray:local ({args.workers} CPUs)"
        configs[name] = (on_engine(name, lambda: (ray_ex, ray_ex.slots), True), args.workers)
    times: dict[str, list[float]] = {name: [] for name in configs}
    with tempfile.TemporaryDirectory(prefix="bench_sweep_") as tmp:
        for k in range(args.repeats):
            for i, (name, (fn, _w)) in enumerate(configs.items()):
                times[name].append(fn(Path(tmp) / f"{k}-{i}", args.runs, args.seconds))
    if ray_mod is not None:
        ray_mod.shutdown()
    load1 = os.getloadavg()
    base = statistics.median(times["one process (baseline)"])
    print(f"{args.runs} runs of {args.seconds:g} s simulated (Method I case I), "
          f"{args.repeats} repeats, medians; {available_cpus()} CPUs")
    bare = base / statistics.median(times[f"{args.workers} bare processes"])
    print(f"{'configuration':28s} {'wall [s]':>9s} {'runs/s':>7s} {'speed-up':>9s} "
          f"{'per worker':>11s} {'of capacity':>12s}")
    for name, (_fn, workers) in configs.items():
        med = statistics.median(times[name])
        speed = base / med
        of_cap = speed / bare if workers > 1 else speed
        print(f"{name:28s} {med:9.2f} {args.runs / med:7.2f} {speed:8.2f}x "
              f"{speed / workers:10.2f}x {of_cap:11.2f}x")
    print(f"'of capacity': the speed-up over that of {args.workers} bare processes doing the "
          f"same runs now ({bare:.2f}x): what the machine gives while others load it")
    for name, starts in STARTUP.items():
        print(f"start-up of {name} (workers, imports; not in the wall time above): "
              f"{statistics.median(starts):.2f} s")
    print("load average (1, 5, 15 min): before " + ", ".join(f"{x:.2f}" for x in load0)
          + "; after " + ", ".join(f"{x:.2f}" for x in load1))


if __name__ == "__main__":
    main()
