"""Real-time settings for a loop process (``--rt`` of ``ffexp run`` and ``ffexp emulate``).

What a Python process on Linux can do for a 1 to 5 ms cycle: ask for
``SCHED_FIFO`` (needs ``CAP_SYS_NICE`` or an rtprio limit; refused otherwise,
and said so), pin to chosen CPUs, and keep the garbage collector out of the
loop (``gc.freeze()`` moves everything allocated so far out of its reach,
``gc.disable()`` stops automatic collections until the context ends). Nothing
here is maths; it changes only how the OS schedules this process.
"""

from __future__ import annotations

import gc
import os
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

#: The SCHED_FIFO priority asked for: high enough to beat ordinary processes, below
#: the kernel's own threaded interrupts (50) so the network stack still runs.
FIFO_PRIORITY = 40


@dataclass
class RealtimeReport:
    """What ``--rt`` obtained, one line each (printed before the run)."""

    lines: list[str] = field(default_factory=list)
    fifo: bool = False
    pinned: tuple[int, ...] = ()

    def __str__(self) -> str:
        return "; ".join(self.lines)


def _fifo(report: RealtimeReport) -> int | None:
    """Ask for SCHED_FIFO; return the old policy to restore, or None when refused."""
    if not hasattr(os, "sched_setscheduler"):
        report.lines.append("real-time scheduling: not available on this OS")
        return None
    old = os.sched_getscheduler(0)
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(FIFO_PRIORITY))
    except PermissionError:
        report.lines.append(
            "real-time scheduling refused (SCHED_FIFO needs CAP_SYS_NICE or an rtprio "
            "limit, e.g. in /etc/security/limits.conf); running at normal priority")
        return None
    report.fifo = True
    report.lines.append(f"SCHED_FIFO priority {FIFO_PRIORITY}")
    return old


@contextmanager
def realtime(cpus: tuple[int, ...] = ()) -> Iterator[RealtimeReport]:
    """Real-time scheduling where the OS allows it, CPU pinning, the GC out of the way.

    Restores the scheduling policy, the affinity and the collector on exit.
    """
    report = RealtimeReport()
    old_policy = _fifo(report)
    old_cpus: set[int] | None = None
    if cpus and hasattr(os, "sched_setaffinity"):
        old_cpus = os.sched_getaffinity(0)
        os.sched_setaffinity(0, set(cpus))
        report.pinned = tuple(sorted(cpus))
        report.lines.append(f"pinned to CPU {', '.join(map(str, report.pinned))}")
    gc.collect()
    gc.freeze()
    was_enabled = gc.isenabled()
    gc.disable()
    report.lines.append("garbage collection frozen and disabled")
    try:
        yield report
    finally:
        if was_enabled:
            gc.enable()
        gc.unfreeze()
        if old_cpus is not None:
            os.sched_setaffinity(0, old_cpus)
        if old_policy is not None:
            os.sched_setscheduler(0, old_policy, os.sched_param(0))
