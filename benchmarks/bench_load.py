"""``load`` of a run's recording against mcap's own reader, same run, same file.

    python benchmarks/bench_load.py [--protocol P] [--set KEY=VALUE ...] [--repeats R]
    python benchmarks/bench_load.py --mcap RUN.mcap [--repeats R]

Makes one run of the protocol on the simulator (default: Method I case I, the
paper's run, as it is) or takes a recording, then times, interleaved per repeat:

- ``load(path)``: chunks read and decoded a topic at once (ffexp.recording.chunks,
  ffexp.recording.columns);
- ``load_with_mcap(path)``: the previous path, every message through mcap's
  ``SeekingReader.iter_messages`` (a ``Message`` object per record), then decoded;
- ``metrics(load(path))`` and ``metrics(load_with_mcap(path))``: what a study
  pays to analyse each run (``ffexp.sweeps.worker``).

Prints the wall-time medians, the CPU-time medians of this process (steadier on a
shared machine) and the ratios previous/new; checks once that both loads give the
same arrays, byte for byte.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ffexp.analysis import metrics
from ffexp.recording import Recording, load
from ffexp.recording.reader import load_with_mcap

ROOT = Path(__file__).resolve().parent.parent


def identical(a: Recording, b: Recording) -> bool:
    """Every array's dtype and bytes, times, JSON messages, metadata and attachments."""
    if list(a.topics) != list(b.topics) or list(a.json) != list(b.json):
        return False
    for name, x in a.topics.items():
        y = b.topics[name]
        if not np.array_equal(x.log_time_ns, y.log_time_ns) or list(x.fields) != list(y.fields):
            return False
        if any(u.dtype != y.fields[f].dtype or u.tobytes() != y.fields[f].tobytes()
               for f, u in x.fields.items()):
            return False
    return (all(np.array_equal(j.log_time_ns, b.json[n].log_time_ns)
                and j.messages == b.json[n].messages for n, j in a.json.items())
            and a.metadata == b.metadata and a.attachments == b.attachments
            and a.warnings == b.warnings)


def timed(f: Callable[[], Any]) -> tuple[float, float]:
    w, c = time.perf_counter(), time.process_time()
    f()
    return time.perf_counter() - w, time.process_time() - c


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--protocol", type=Path, default=ROOT / "protocols/method1_case1.toml")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="an override of the run (repeatable)")
    ap.add_argument("--mcap", type=Path, help="time this recording instead of making a run")
    ap.add_argument("--repeats", type=int, default=15)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = args.mcap
        if path is None:
            from ffexp.experiment import run_file

            path = run_file(args.protocol, args.set, out_dir=Path(tmp)).path
        rec = load(path)
        cycles = len(rec.topics["/robot/state"]) if "/robot/state" in rec.topics else 0
        messages = sum(len(d) for d in (*rec.topics.values(), *rec.json.values()))
        same = identical(rec, load_with_mcap(path))
        cases: dict[str, Callable[[], Any]] = {
            "load": lambda: load(path),
            "load_with_mcap": lambda: load_with_mcap(path),
            "metrics(load)": lambda: metrics(load(path)),
            "metrics(load_with_mcap)": lambda: metrics(load_with_mcap(path)),
        }
        for f in cases.values():  # warm up: imports, numba, page cache
            f()
        wall: dict[str, list[float]] = {k: [] for k in cases}
        cpu: dict[str, list[float]] = {k: [] for k in cases}
        for _ in range(args.repeats):
            for name, f in cases.items():
                w, c = timed(f)
                wall[name].append(w)
                cpu[name].append(c)
        size_mb = path.stat().st_size / 1e6
    load_avg = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"{path.name}: {cycles} cycles, {messages} messages, {size_mb:.2f} MB; "
          f"{args.repeats} repeats, load average {load_avg:.1f}")
    print(f"identical arrays, times, JSON, metadata: {'yes' if same else 'NO'}")
    med = {k: (statistics.median(wall[k]), statistics.median(cpu[k])) for k in cases}
    for name, (w, c) in med.items():
        per = f"  {w / cycles * 1e6:6.1f} us/cycle" if cycles else ""
        print(f"{name:25s} wall {w * 1e3:8.1f} ms  cpu {c * 1e3:8.1f} ms{per}")
    for new, old in (("load", "load_with_mcap"), ("metrics(load)", "metrics(load_with_mcap)")):
        print(f"ratio {old} / {new}: wall {med[old][0] / med[new][0]:.2f}x, "
              f"cpu {med[old][1] / med[new][1]:.2f}x")


if __name__ == "__main__":
    main()
