"""A batched study's refills against shrinking batches: wall time of the same study.

    python benchmarks/bench_refill.py [--runs R] [--seconds S] [--workers W]
                                      [--batch B] [--repeats K] [--lean]

The study of ``bench_study.py`` (R runs of the paper's methods in turn, Method I
case I and II, Method II, Method III, one noise seed each, ``run.timeout_s=S``: runs
that end at different times, as they align, abort or time out) through the sweep
engine on ``--executor local:W,batch:B`` two ways, interleaved per repeat:

* **refill** (the default): each batch process keeps B runs live; when one ends, a
  queued job joins the running batch between two dispatches, and each run's row goes
  back to the engine as the run ends (:class:`ffexp.sweeps.batch.RefillExecutor`);
* **shrink**: each process is given a batch of up to B jobs, which shrinks as its
  runs end, and takes its next batch only when its last run ended; a batch's rows go
  back together (:class:`ffexp.sweeps.batch.BatchExecutor`, as on Ray).

``--spread``: every other run times out at a quarter of S (lengths that differ much).
Prints every repeat's wall time, the medians and refill / shrink, the runs'
simulated durations, and the load average before and after (the workers' start-up
is not counted: warm-up tasks import what a run needs first).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
from dataclasses import replace
from pathlib import Path

from bench_study import PROTOCOLS, make_jobs, study, warm_worker

from ffexp.sweeps.executors import available_cpus
from ffexp.sweeps.worker import Job


def refill_against_shrink(jobs: list[Job], tmp: Path, workers: int, batch: int,
                          repeats: int) -> None:
    """The batched study with refills (a run's slot taken by a queued job as it ends,
    its row back then) against shrinking batches (a process's next batch when its last
    run ended), interleaved per repeat: wall times, medians; how long the runs took."""
    spec = f"local:{workers},batch:{batch}"
    paths = {"refill": study(spec, 2 * workers, refill=True),
             "shrink": study(spec, 2 * workers, refill=False)}
    times: dict[str, list[float]] = {name: [] for name in paths}
    for k in range(repeats):
        for name, run in paths.items():
            times[name].append(run(tmp / f"{name}{k}", jobs))
            print(f"  repeat {k}: {name} {times[name][-1]:.2f} s", flush=True)
    durations = [json.loads(p.read_text())["duration_s"]
                 for p in (tmp / "refill0" / "runs").glob("*/row.json")]
    print(f"{len(jobs)} runs ({', '.join(PROTOCOLS)}), their simulated durations "
          f"{min(durations):.2f} to {max(durations):.2f} s (median "
          f"{statistics.median(durations):.2f} s); {spec}; {repeats} repeats, medians")
    for name, t in times.items():
        print(f"  {name}: {statistics.median(t):.2f} s (all: "
              + ", ".join(f"{x:.2f}" for x in t) + ")")
    ratio = statistics.median(times["refill"]) / statistics.median(times["shrink"])
    print(f"  refill / shrink: {ratio:.3f}")


def spread(job: Job, seconds: float) -> Job:
    """``job`` timing out at ``seconds`` instead."""
    return replace(job, overrides=tuple(f"run.timeout_s={seconds}"
                                        if o.startswith("run.timeout_s=") else o
                                        for o in job.overrides))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=32)
    ap.add_argument("--seconds", type=float, default=8.0, help="run.timeout_s of each run")
    ap.add_argument("--workers", type=int, default=available_cpus())
    ap.add_argument("--batch", type=int, default=8, help="runs per batch")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--lean", action="store_true", help="the runs record lean")
    ap.add_argument("--spread", action="store_true",
                    help="every other run times out at a quarter of --seconds (lengths "
                    "that differ much)")
    args = ap.parse_args()
    warm_worker()
    load0 = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="bench_refill_") as tmp_name:
        tmp = Path(tmp_name)
        jobs = make_jobs(tmp / "jobs", args.runs, args.seconds, args.lean)
        if args.spread:
            jobs = [spread(j, args.seconds / 4) if k % 2 else j for k, j in enumerate(jobs)]
        refill_against_shrink(jobs, tmp, args.workers, args.batch, args.repeats)
    load1 = os.getloadavg()
    print("load average (1, 5, 15 min): before " + ", ".join(f"{x:.2f}" for x in load0)
          + "; after " + ", ".join(f"{x:.2f}" for x in load1))


if __name__ == "__main__":
    main()
