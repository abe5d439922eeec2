"""``ffexp calibrate --batch``: the acceptance fit's rollouts stepped together, against
today's pool (one rollout at a time per process); the same fitted numbers.

Records the runs of ``bench_calibrate.py`` (6 to fit, 2 held out, at the parameters set
there), then fits them ``--repeats`` times each way, interleaved: ``--jobs`` processes
with the rollouts one at a time (``--batch 1``, today) and with up to ``--batch B``
rollouts of a call stepped together per process (one physics dispatch a cycle).
Prints each fit's wall time, the medians and their ratio, and whether every fitted
value, interval and rollout count is the same bits both ways.

    .venv/bin/python benchmarks/bench_calibrate_batch.py [--jobs 2] [--batch 4]
        [--repeats 2] [--keys KEY ...]
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from dataclasses import asdict
from pathlib import Path

from bench_calibrate import FIT_RUNS, HOLDOUT_RUNS, ROOT, TRUTH, record


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--batch", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--keys", nargs="*", default=list(TRUTH), help="the keys to fit")
    args = ap.parse_args()
    from ffexp.calibrate.run import calibrate

    load0 = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        fit_paths = record(Path(tmp), FIT_RUNS)
        held = record(Path(tmp), HOLDOUT_RUNS)
        print(f"recorded {len(fit_paths)} + {len(held)} runs in {time.perf_counter() - t:.1f} s")
        times: dict[int, list[float]] = {1: [], args.batch: []}
        results = {}
        for k in range(args.repeats):
            for batch in times:
                t0 = time.perf_counter()
                res, _ = calibrate(fit_paths, args.keys, ROOT / "data/scenes/paper.toml",
                                   holdout=held, jobs=args.jobs, batch=batch)
                times[batch].append(time.perf_counter() - t0)
                results[batch] = res
                print(f"  repeat {k}: --batch {batch}: {times[batch][-1]:.1f} s "
                      f"({res.rollouts} rollouts)", flush=True)
    load1 = os.getloadavg()
    a, b = results[1], results[args.batch]
    same = (a.values == b.values and a.rollouts == b.rollouts
            and [asdict(e) for e in a.estimates] == [asdict(e) for e in b.estimates])
    med = {batch: statistics.median(t) for batch, t in times.items()}
    print(f"fit of {len(fit_paths)} recordings (+{len(held)} held out), keys "
          f"{', '.join(args.keys)}; {args.jobs} processes; {args.repeats} repeats, medians:")
    for batch, m in med.items():
        print(f"  --batch {batch}: {m:.1f} s (all: " + ", ".join(f"{x:.1f}" for x in times[batch])
              + ")")
    print(f"  --batch {args.batch} / --batch 1: {med[args.batch] / med[1]:.3f}; the same fitted "
          f"numbers bit for bit: {'yes' if same else 'NO'}")
    print("load average (1, 5, 15 min): before " + ", ".join(f"{x:.2f}" for x in load0)
          + "; after " + ", ".join(f"{x:.2f}" for x in load1))
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
