"""One run of a sweep, in a worker process (local pool or Ray): run, analyse, commit.

A run writes into its own temporary folder ``DIR/runs/.tmp-<id>-<host>-<pid>-<rand>/``
(the MCAP file and ``row.json``) and is renamed to ``DIR/runs/<id>/`` only when
it finished, so a killed sweep leaves nothing that counts as done; the rename
is atomic, so two workers that ran the same id keep exactly one result. A
run that raises is a finished run too: its row carries the error.
"""

from __future__ import annotations

import json
import math
import os
import platform
import shutil
import time
import uuid
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

ROW_FILE = "row.json"
RUN_FILE = "run.mcap"
RUNS_DIR = "runs"
INPUTS_DIR = "inputs"
TMP_PREFIX = ".tmp-"
#: Axis names of the six-vector metrics (columns ``mean_abs_wrench_align_fx`` ...).
WRENCH_AXES = ("fx", "fy", "fz", "tx", "ty", "tz")


@dataclass(frozen=True)
class Job:
    """Everything a worker needs (small, picklable): a run is fully determined by it."""

    run_id: str
    protocol: str
    overrides: tuple[str, ...]
    out_dir: str
    columns: dict[str, Any] = field(default_factory=dict)
    """The sweep's own columns of the row (target, the varied keys, seed)."""


def run_dir(out_dir: Path, rid: str) -> Path:
    return out_dir / RUNS_DIR / rid


def read_row(out_dir: Path, rid: str) -> dict[str, Any] | None:
    """The committed row of a run, or None when it is not done."""
    try:
        data: dict[str, Any] = json.loads((run_dir(out_dir, rid) / ROW_FILE).read_text())
    except (FileNotFoundError, NotADirectoryError, json.JSONDecodeError):
        return None
    return data


def flat_metrics(m: Any) -> dict[str, Any]:
    """The metrics of ``ffexp analyze --json`` as flat, typed columns: six-vectors
    become one column per axis, the link summary ``link_<name>``, the list of break
    times JSON text."""
    out: dict[str, Any] = {}
    for key, value in asdict(m).items():
        if key in ("mean_abs_wrench_align", "peak_abs_wrench_align"):
            vec = value if value is not None else [None] * 6
            out.update({f"{key}_{a}": v for a, v in zip(WRENCH_AXES, vec, strict=True)})
        elif key == "link":
            out.update({f"link_{k}": v for k, v in sorted(value.items())})
        elif key == "break_times_s":
            out[key] = json.dumps(value)
        elif key == "warnings":
            out[key] = "; ".join(value)
        else:
            out[key] = value
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
            for k, v in out.items()}


def run_one(job: Job) -> dict[str, Any]:
    """Run a job (unless it is already done) and return its row."""
    out_dir = Path(job.out_dir)
    done = read_row(out_dir, job.run_id)
    if done is not None:
        return done
    tmp = out_dir / RUNS_DIR / (
        f"{TMP_PREFIX}{job.run_id}-{platform.node()}-{os.getpid()}-{uuid.uuid4().hex[:6]}"
    )
    tmp.mkdir(parents=True)
    t0 = time.perf_counter()
    error: str | None = None
    values: dict[str, Any] = {}
    try:
        values = _run_and_analyse(job, tmp)
    except Exception as exc:  # a failing run is a row with its error, never the sweep's end
        error = f"{type(exc).__name__}: {exc}".splitlines()[0]
    row = {
        "run_id": job.run_id, **job.columns, **values, "error": error,
        "wall_s": time.perf_counter() - t0,
        "path": f"{RUNS_DIR}/{job.run_id}/{RUN_FILE}" if error is None else None,
    }
    (tmp / ROW_FILE).write_text(json.dumps(row, allow_nan=False) + "\n")
    final = run_dir(out_dir, job.run_id)
    try:
        tmp.rename(final)
    except OSError:  # another worker committed the same run first: keep its result
        shutil.rmtree(tmp, ignore_errors=True)
        return read_row(out_dir, job.run_id) or row
    return row


def _run_and_analyse(job: Job, tmp: Path) -> dict[str, Any]:
    from ffexp.analysis import metrics
    from ffexp.experiment import run_file
    from ffexp.recording import load

    result = run_file(Path(job.protocol), list(job.overrides), out_dir=tmp)
    path = result.path.rename(tmp / RUN_FILE)
    return flat_metrics(metrics(load(path)))


def worker_init() -> None:
    """Process-pool workers ignore Ctrl-C: the sweep decides (it lets running runs
    finish, or ends the workers on a second Ctrl-C)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
