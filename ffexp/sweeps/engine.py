"""The sweep engine: jobs onto an Executor, done runs skipped, rows back, a table written.

One :class:`Runner` per output directory ``DIR`` (a lock file keeps a second
sweep out of it):

- ``DIR/runs/<id>/`` a finished run: ``run.mcap`` and ``row.json``;
- ``DIR/runs/.tmp-*`` runs in progress (a killed sweep's are removed on start);
- ``DIR/inputs/<protocol>-<hash>/`` the protocol and scene every worker reads;
- ``DIR/results.csv``, ``DIR/results.parquet`` the table, ``DIR/figures/``.

:meth:`Runner.run_batch` is thread-safe: ``ffexp limits`` and ``ffexp
reproduce`` run several searches at once through one Runner. A job whose id
is done is not submitted; a job whose id is already running is joined.

The Runner records its runs lean or full (``lean``: every job is run with it, whatever
it says): a done run counts only when its recording serves the Runner's
(:func:`~ffexp.sweeps.worker.serves`: a full one always, a lean one for a lean Runner);
a lean run in a full Runner is run again, full.
"""

from __future__ import annotations

import dataclasses
import functools
import shutil
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, Executor, Future, wait
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ffexp.errors import ConfigError
from ffexp.sweeps.worker import (
    INPUTS_DIR,
    RUNS_DIR,
    TMP_PREFIX,
    Job,
    done_row,
    run_one,
)

#: How often a waiting batch wakes up to look at the stop flag (s).
POLL_S = 0.25
#: How long the end of ended workers' runs is waited for (their counts) [s].
SETTLE_S = 10.0
LOCK_FILE = ".lock"


@dataclass
class Counts:
    """What the progress bar shows."""

    total: int = 0
    """Runs submitted or found done so far."""
    done: int = 0
    skipped: int = 0
    running: int = 0
    failed: int = 0
    stopped: int = 0
    """Runs a signal ended before they finished (not failures: run again, they run)."""
    planned: int = 0
    """Runs expected in all (:meth:`Runner.plan`): a plan that grows as it runs (limit
    searches bisect) is counted ahead, so the time left is for all of it."""
    run_s: float = 0.0
    """Wall time of the runs finished in this session (their own ``wall_s``)."""
    slots: int = 1
    """Runs at once."""


class Stopped(Exception):
    """The sweep was asked to stop (a signal); finished runs are kept."""


class Runner:
    """Runs jobs on an executor into ``out_dir``; see the module doc."""

    def __init__(
        self,
        out_dir: Path,
        executor: Executor | Callable[[], Executor],
        slots: int,
        *,
        on_change: Callable[[Counts], None] | None = None,
        stop_requested: Callable[[], bool] = lambda: False,
        notice: Callable[[str], None] | None = None,
        lean: bool = False,
    ) -> None:
        self.out_dir = out_dir.resolve()
        self.lean = lean
        """Record the runs lean (the topics the metrics read)."""
        self._executor = executor
        self.slots = max(1, slots)
        self.counts = Counts(slots=self.slots)
        self._on_change = on_change
        self._stop_requested = stop_requested
        self._lock = threading.RLock()  # a done callback may run inside submit's lock
        self._settled = threading.Condition(self._lock)
        self._inflight: dict[str, Future[dict[str, Any]]] = {}
        self._lock_fh: Any = None
        self._notice = notice
        self._stop_noted = False

    # -- directory -----------------------------------------------------------------
    def open(self) -> Runner:
        """Create and lock the directory; remove runs a killed sweep left unfinished."""
        import fcntl

        if self.out_dir.exists() and not self.out_dir.is_dir():
            raise ConfigError("--out", str(self.out_dir), "exists and is not a directory")
        try:
            (self.out_dir / RUNS_DIR).mkdir(parents=True, exist_ok=True)
            self._lock_fh = (self.out_dir / LOCK_FILE).open("a")
        except OSError as exc:
            raise ConfigError("--out", str(self.out_dir), f"cannot write: {exc.strerror}") \
                from None
        try:
            fcntl.flock(self._lock_fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            self._lock_fh.close()
            self._lock_fh = None
            raise ConfigError("--out", str(self.out_dir),
                              "another sweep is writing into this directory") from None
        for stale in (self.out_dir / RUNS_DIR).glob(f"{TMP_PREFIX}*"):
            shutil.rmtree(stale, ignore_errors=True)
        return self

    def close(self) -> None:
        if self._lock_fh is not None:
            self._lock_fh.close()
            self._lock_fh = None

    def __enter__(self) -> Runner:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def executor(self) -> Executor:
        """The executor (a factory given to the Runner is called on the first run)."""
        if not isinstance(self._executor, Executor):
            self._executor = self._executor()
        return self._executor

    @property
    def started(self) -> Executor | None:
        """The executor if it exists (nothing to shut down otherwise)."""
        return self._executor if isinstance(self._executor, Executor) else None

    @property
    def inputs(self) -> Path:
        return self.out_dir / INPUTS_DIR

    # -- running -------------------------------------------------------------------
    def _changed(self) -> None:
        if self._on_change is not None:
            self._on_change(self.counts)

    def plan(self, runs: int) -> None:
        """Say how many runs the whole plan will have (an estimate ahead of the runs a
        search adds as it goes); the time left counts them."""
        with self._lock:
            self.counts.planned = runs
            self._changed()

    def _finished(self, rid: str, fut: Future[dict[str, Any]]) -> None:
        with self._lock:
            self._inflight.pop(rid, None)
            self.counts.running = min(len(self._inflight), self.slots)
            if fut.cancelled():
                self.counts.total -= 1
            elif fut.exception() is not None and self._stop_requested():
                self.counts.total -= 1  # a worker a signal ended: stopped, not failed
                self.counts.stopped += 1
            else:
                self.counts.done += 1
                exc = fut.exception()
                if exc is not None or fut.result().get("error"):
                    self.counts.failed += 1
                else:
                    self.counts.run_s += float(fut.result().get("wall_s") or 0.0)
            self._changed()
            if self._stop_requested():  # before an executor starts the next runs in turn
                for other in list(self._inflight.values()):
                    if not other.running():
                        other.cancel()
            self._settled.notify_all()

    def settle(self, timeout_s: float) -> bool:
        """Wait until no run is in flight (their ends counted), at most ``timeout_s``:
        after the workers were ended, so the last counts say what became of them."""
        with self._settled:
            return self._settled.wait_for(lambda: not self._inflight, timeout_s)

    def _note_stop(self) -> None:
        with self._lock:
            if self._stop_noted or self._notice is None:
                return
            self._stop_noted = True
            running = min(len(self._inflight), self.slots)  # the others never started
        if running:
            self._notice(f"stopping: waiting for the {running} run(s) already started "
                         "(interrupt again to abandon them)")

    def run_batch(self, jobs: Sequence[Job]) -> list[dict[str, Any]]:
        """Rows of ``jobs`` in order: done ones read back, the others run.

        A worker that dies (not a run that fails: that is a row with its error)
        gives a row with the error that is not committed, so a later sweep runs it
        again. Raises :class:`Stopped` when asked to stop; running runs finish.
        """
        rows: dict[str, dict[str, Any]] = {}
        waiting: dict[str, Future[dict[str, Any]]] = {}
        jobs = [job if job.lean == self.lean else dataclasses.replace(job, lean=self.lean)
                for job in jobs]
        with self._lock:
            for job in jobs:
                if job.run_id in rows or job.run_id in waiting:
                    continue
                done = done_row(self.out_dir, job)
                if done is not None:
                    rows[job.run_id] = done
                    self.counts.total += 1
                    self.counts.done += 1
                    self.counts.skipped += 1
                    if done.get("error"):
                        self.counts.failed += 1
                    continue
                fut = self._inflight.get(job.run_id)
                if fut is None:
                    if self._stop_requested():
                        raise Stopped
                    fut = self.executor.submit(run_one, job)
                    self._inflight[job.run_id] = fut
                    self.counts.total += 1
                    fut.add_done_callback(functools.partial(self._finished, job.run_id))
                waiting[job.run_id] = fut
            self.counts.running = min(len(self._inflight), self.slots)
            self._changed()
        flush = getattr(self.started, "flush", None)
        if flush is not None:  # an executor that groups jobs (batch): these are all for now
            flush()
        pending = set(waiting.values())
        while pending:
            _, pending = wait(pending, timeout=POLL_S, return_when=FIRST_COMPLETED)
            if self._stop_requested() and pending:
                for fut in pending:
                    fut.cancel()
                self._note_stop()
        by_job = {job.run_id: job for job in jobs}
        for rid, fut in waiting.items():
            if fut.cancelled():
                raise Stopped
            exc = fut.exception()
            if exc is not None:
                rows[rid] = {"run_id": rid, **by_job[rid].columns,
                             "error": f"worker failed: {type(exc).__name__}: {exc}",
                             "wall_s": None, "path": None}
            else:
                rows[rid] = fut.result()
        if self._stop_requested():
            raise Stopped
        return [rows[job.run_id] for job in jobs]


def eta_s(counts: Counts, started: float, now: float | None = None) -> float | None:
    """Seconds left (None before a run of this session finished): the runs left of the
    whole plan (:attr:`Counts.planned` when more than submitted so far; a running run
    counts half) times the mean wall time of a finished run, over the slots. Without
    the runs' own times (a failed run has none): from the rate of finished runs."""
    ran = counts.done - counts.skipped
    if ran <= 0:
        return None
    left = max(counts.total, counts.planned) - counts.done - counts.running / 2
    ok = ran - counts.failed
    if ok > 0 and counts.run_s > 0:
        return max(0.0, left) * (counts.run_s / ok) / max(1, counts.slots)
    elapsed = (time.monotonic() if now is None else now) - started
    return elapsed / ran * max(0.0, left)
