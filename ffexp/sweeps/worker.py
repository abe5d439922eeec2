"""One run of a sweep, in a worker process (local pool or Ray): run, analyse, commit.

A run writes into its own temporary folder ``DIR/runs/.tmp-<id>-<host>-<pid>-<rand>/``
(the MCAP file and ``row.json``) and is renamed to ``DIR/runs/<id>/`` only when
it finished, so a killed sweep leaves nothing that counts as done; the rename
is atomic, so two workers that ran the same id keep exactly one result. A
run that raises is a finished run too: its row carries the error.

A run is recorded full or lean (:attr:`Job.lean`; :mod:`ffexp.runlog`); its row says
which (``recording``: ``full`` or ``lean``; a row without it is from before lean
recordings, full). The row's numbers are the same either way, so a run's id does not
depend on it, but a done run counts as done only for a job its recording serves
(:func:`serves`): a full one for any job, a lean one only for a lean job. A lean run
asked for full is run again and its result replaced (:func:`run_one`).
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

from ffexp.rig_choice import RigChoice

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
    """The sweep's own columns of the row (target, rig, the varied keys, seed)."""
    lean: bool = False
    """Record only the topics the metrics read (the row's numbers are the same)."""
    rig: str | None = None
    """The rig file (its copy in the study's ``inputs/``); ``None``: a built-in rig."""
    rig_overrides: tuple[str, ...] = ()
    """``dotted.key=value`` overrides of the rig's fields (``--rig-set``)."""
    driver: str | None = None
    """Without :attr:`rig`: the built-in rig's ``--driver`` (``None``: the default)."""

    def rig_choice(self) -> RigChoice:
        """The rig of the run, as :func:`ffexp.experiment.run_file` takes it."""
        return RigChoice(Path(self.rig) if self.rig else None, self.rig_overrides,
                         None if self.rig else self.driver)


def recording_kind(lean: bool) -> str:
    """The ``recording`` column of a row: ``lean`` or ``full``."""
    return "lean" if lean else "full"


def serves(row: dict[str, Any], job: Job) -> bool:
    """Whether a done run's ``row`` is a result for ``job``: a full recording serves any
    job, a lean one only a lean job (rows from before lean recordings are full)."""
    return job.lean or row.get("recording", "full") != "lean"


def run_dir(out_dir: Path, rid: str) -> Path:
    return out_dir / RUNS_DIR / rid


def read_row(out_dir: Path, rid: str) -> dict[str, Any] | None:
    """The committed row of a run, or None when it is not done (a row from before lean
    recordings gets ``recording`` ``full``: every run was recorded full)."""
    try:
        data: dict[str, Any] = json.loads((run_dir(out_dir, rid) / ROW_FILE).read_text())
    except (FileNotFoundError, NotADirectoryError, json.JSONDecodeError):
        return None
    data.setdefault("recording", "full")
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


def with_columns(row: dict[str, Any], job: Job) -> dict[str, Any]:
    """A done run's row with the job's columns it lacks (``rig``: rows from before studies
    took a rig have none; the run's own values are kept)."""
    if all(k in row for k in job.columns):
        return row
    return {"run_id": row.get("run_id", job.run_id), **job.columns, **row}


def done_row(out_dir: Path, job: Job) -> dict[str, Any] | None:
    """The committed row of ``job`` in ``out_dir`` when it serves the job (:func:`serves`),
    with the job's columns it lacks (:func:`with_columns`); ``None``: to be run."""
    done = read_row(out_dir, job.run_id)
    return with_columns(done, job) if done is not None and serves(done, job) else None


def run_one(job: Job) -> dict[str, Any]:
    """Run a job (unless it is already done, :func:`done_row`) and return its row."""
    out_dir = Path(job.out_dir)
    done = done_row(out_dir, job)
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
        "recording": recording_kind(job.lean),
    }
    (tmp / ROW_FILE).write_text(json.dumps(row, allow_nan=False) + "\n")
    return _commit(out_dir, job, tmp, row)


def _commit(out_dir: Path, job: Job, tmp: Path, row: dict[str, Any]) -> dict[str, Any]:
    """Rename the finished run's folder ``tmp`` to the run's own; a done run there that
    does not serve ``job`` (lean, this one full) is replaced (moved aside first: a
    crash in between leaves the run not done, to be run again)."""
    final = run_dir(out_dir, job.run_id)
    try:
        tmp.rename(final)
        return row
    except OSError:
        pass
    there = read_row(out_dir, job.run_id)
    if there is None or serves(there, job):  # another worker committed it first: keep it
        shutil.rmtree(tmp, ignore_errors=True)
        return row if there is None else with_columns(there, job)
    old = final.with_name(f"{TMP_PREFIX}{job.run_id}-replaced-{uuid.uuid4().hex[:6]}")
    try:
        final.rename(old)
        tmp.rename(final)
    except OSError:  # another worker replaced it meanwhile: keep what is there
        shutil.rmtree(tmp, ignore_errors=True)
        return read_row(out_dir, job.run_id) or row
    finally:  # (the lean run moved aside; a .tmp- folder: a sweep's start removes it too)
        shutil.rmtree(old, ignore_errors=True)
    return row


def _run_and_analyse(job: Job, tmp: Path) -> dict[str, Any]:
    from ffexp.analysis import metrics
    from ffexp.experiment import run_file
    from ffexp.recording import load

    result = run_file(Path(job.protocol), list(job.overrides), rig=job.rig_choice(),
                      out_dir=tmp, lean=job.lean)
    path = result.path.rename(tmp / RUN_FILE)
    return flat_metrics(metrics(load(path)))


def worker_init() -> None:
    """Process-pool workers ignore Ctrl-C: the sweep decides (it lets running runs
    finish, or ends the workers on a second Ctrl-C)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
