"""A sweep session for the commands: the executor, the Runner and the progress bar.

The bar (rich, on stderr) shows done/total, running, failed, skipped (done
before) and the time left; it redraws several times a second, so a terminal
is never silent. Without a terminal a line is printed at most every
:data:`PLAIN_PERIOD_S` and at the end. Ctrl-C (or SIGTERM) stops submitting
and lets the running runs finish (they are kept); a second one ends the
workers at once (their runs are lost, nothing half-written counts as done).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from ffexp.sweeps.engine import SETTLE_S, Counts, Runner, eta_s
from ffexp.sweeps.executors import ExecutorSpec, end_workers, make_executor, start_forkserver

PLAIN_PERIOD_S = 5.0


def _fmt_s(s: float | None) -> str:
    if s is None:
        return "-:--"
    s = max(0.0, s)
    return f"{int(s // 3600)}:{int(s % 3600 // 60):02d}:{int(s % 60):02d}"


class Display:
    """The progress of a session (a rich bar on a terminal, sparse lines otherwise)."""

    def __init__(self, label: str, enabled: bool | None = None) -> None:
        self.label = label
        self.tty = sys.stderr.isatty() if enabled is None else enabled
        self.started = time.monotonic()
        self._progress: Any = None
        self._task: Any = None
        self._last_line = 0.0
        self._counts = Counts()

    def start(self) -> None:
        if not self.tty:
            return
        from rich.console import Console
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            SpinnerColumn,
            TextColumn,
        )

        self._progress = Progress(
            SpinnerColumn(), TextColumn("{task.description}"), BarColumn(bar_width=12),
            MofNCompleteColumn(), TextColumn("{task.fields[status]}"),
            TextColumn("ETA {task.fields[eta]}"),
            console=Console(stderr=True), refresh_per_second=4,
        )
        self._progress.start()
        self._task = self._progress.add_task(self.label, total=None, status="starting",
                                             eta="-:--")

    def note(self, text: str) -> None:
        if self._progress is not None:
            self._progress.console.print(text)
        else:
            print(text, file=sys.stderr, flush=True)

    def status(self, text: str) -> None:
        """A step before the runs (starting Ray, checking the points)."""
        if self._progress is not None:
            self._progress.update(self._task, status=text)
        elif text.endswith("..."):
            print(f"{self.label}: {text}", file=sys.stderr, flush=True)

    def update(self, counts: Counts) -> None:
        self._counts = Counts(**vars(counts))
        status = (f"running {counts.running} failed {counts.failed} "
                  f"done before {counts.skipped}")
        if counts.stopped:
            status += f" stopped {counts.stopped}"
        eta = _fmt_s(eta_s(counts, self.started))
        if self._progress is not None:
            self._progress.update(self._task, total=max(counts.total, counts.planned),
                                  completed=counts.done, status=status, eta=eta)
            return
        now = time.monotonic()
        if now - self._last_line >= PLAIN_PERIOD_S:
            self._last_line = now
            self._line(eta)

    def _line(self, eta: str) -> None:
        c = self._counts
        total = max(c.total + c.stopped, c.planned)
        stopped = f", {c.stopped} stopped" if c.stopped else ""
        print(f"{self.label}: {c.done}/{total} done, {c.running} running, {c.failed} failed"
              f"{stopped}, {c.skipped} done before, ETA {eta}", file=sys.stderr, flush=True)

    def stop(self) -> None:
        if self._progress is not None:
            self._progress.stop()
            self._progress = None
        elif self._counts.total or self._counts.stopped:
            c = self._counts
            whole = c.done >= max(c.total, c.planned) and not c.stopped
            self._line("0:00:00" if whole else "-:--")


@contextmanager
def spinner(tty: bool, text: str) -> Iterator[None]:
    """A transient spinner on a terminal (it leaves no line behind); nothing otherwise."""
    if not tty:
        yield
        return
    from rich.console import Console

    with Console(stderr=True).status(text):
        yield


@contextmanager
def session(
    out_dir: Path, spec: ExecutorSpec, label: str, stop_requested: Callable[[], bool],
    display: Display | None = None, lean: bool = False,
) -> Iterator[tuple[Runner, Display]]:
    """Executor + Runner + Display; everything is closed at the end, workers ended on a
    second interrupt. ``lean``: the runs record lean (:class:`Runner`)."""
    shown = display or Display(label)
    runner: Runner
    if "ray" in (spec.kind, spec.over):  # connect first: unreachable is one error line
        with spinner(shown.tty, f"{label}: connecting to Ray ({spec.address})"):
            executor, slots = make_executor(spec)
        runner = Runner(out_dir, executor, slots, on_change=shown.update,
                        stop_requested=stop_requested, notice=shown.note, lean=lean)
    else:  # a process pool starts on the first run that is not done yet
        start_forkserver()  # here, in the main thread: it ignores a process group's SIGTERM
        runner = Runner(out_dir, lambda: make_executor(spec)[0], spec.workers,
                        on_change=shown.update, stop_requested=stop_requested,
                        notice=shown.note, lean=lean)
    shown.start()
    try:
        try:
            with runner:
                shown.status(f"{runner.slots} at once on {spec.label}")
                try:
                    yield runner, shown
                except KeyboardInterrupt:
                    if runner.started is not None:
                        end_workers(runner.started)
                        runner.settle(SETTLE_S)  # their runs counted as stopped
                    raise
        finally:
            if runner.started is not None:
                runner.started.shutdown(wait=True, cancel_futures=True)
    finally:
        shown.stop()
