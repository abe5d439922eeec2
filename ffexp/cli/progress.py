"""Progress of long steps: rich bars on a terminal, sparse lines otherwise.

One :class:`Steps` per command; it shows a spinner or a bar for every long
step (starting the simulator, a run, loading recordings, drawing figures) so
that a terminal is never silent for more than a second. When stderr is not a
terminal (CI, a pipe, tests) it prints a run's state at most every 5 s of run
time and nothing for the other steps. rich is imported when a terminal is
there, never at module import.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ffexp.contracts import Progress as RunProgress

#: Without a terminal: a run's state line at most this often (run time).
PLAIN_PERIOD_S = 5.0


class Steps:
    """Bars for one command; a context manager (the bars end with the block)."""

    def __init__(self, enabled: bool | None = None) -> None:
        self.enabled = sys.stderr.isatty() if enabled is None else enabled
        self._progress: Any = None

    def __enter__(self) -> Steps:
        if self.enabled:
            from rich.console import Console
            from rich.progress import (
                BarColumn,
                Progress,
                SpinnerColumn,
                TextColumn,
                TimeElapsedColumn,
            )

            self._progress = Progress(
                SpinnerColumn(),
                TextColumn("{task.description}"),
                BarColumn(bar_width=16),
                TextColumn("{task.fields[status]}"),
                TimeElapsedColumn(),
                console=Console(stderr=True),
                transient=False,
            )
            self._progress.start()
        return self

    def __exit__(self, *exc: object) -> None:
        if self._progress is not None:
            self._progress.stop()
            self._progress = None

    @contextmanager
    def step(self, description: str, total: float | None = None) -> Iterator[Callable[..., None]]:
        """A transient step; yields ``advance(n=1, status="")``."""
        if self._progress is None:
            yield lambda n=1, status="": None
            return
        bar = self._progress
        task = bar.add_task(description, total=total, status="")

        def advance(n: float = 1, status: str = "") -> None:
            bar.update(task, advance=n, status=status)

        try:
            yield advance
        finally:
            bar.remove_task(task)

    @contextmanager
    def run(
        self, label: str, timeout_s: float
    ) -> Iterator[Callable[[RunProgress], None]]:
        """One run's bar over its run time (the protocol's timeout is the whole bar).

        Until the first cycle it is a "starting" spinner (devices, the simulator).
        """
        if self._progress is None:
            last = [-PLAIN_PERIOD_S]

            def show_plain(p: RunProgress) -> None:
                if p.time_s - last[0] >= PLAIN_PERIOD_S:
                    last[0] = p.time_s
                    print(f"{label}: {_status(p)}", file=sys.stderr, flush=True)

            yield show_plain
            return
        bar = self._progress
        task = bar.add_task(f"{label} (starting)", total=None, status="")
        started = [False]

        def show(p: RunProgress) -> None:
            if not started[0]:
                started[0] = True
                bar.update(task, description=label, total=timeout_s)
            bar.update(task, completed=min(p.time_s, timeout_s), status=_status(p))

        try:
            yield show
        finally:
            bar.update(task, completed=timeout_s if started[0] else 0)
            bar.stop_task(task)

    def note(self, line: str) -> None:
        """A line above the bars (or on stderr without a terminal)."""
        if self._progress is not None:
            self._progress.console.print(line, markup=False, highlight=False)
        else:
            print(line, file=sys.stderr, flush=True)


def _status(p: RunProgress) -> str:
    return f"{p.phase.name:<8} {p.time_s:5.1f} s  f_z {p.f_z_n:+5.2f} N  breaks {p.breaks}"
