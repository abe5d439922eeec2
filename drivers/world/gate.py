"""The physics gate: several worlds' control cycles stepped together, one dispatch a cycle.

A batch of runs in one process runs each run's own code, unchanged, as a
greenlet (a coroutine with its own stack) on one thread: :meth:`PhysicsGate.run`.
The world's physics call (:class:`~drivers.world.ftsensor.FtSteps`, one
``mj_step`` of a cycle's substeps) goes through the gate active where the world
was built (:func:`use_gate`, a context variable each run's greenlet sets): the
run hands its ``(model, data, nstep)`` to the gate and is suspended there. When
every live run has handed in its cycle, one dispatch steps them all and each
run resumes with its own data, which ``mj_step`` changed exactly as alone (each
run keeps its own model and data: the result depends neither on the thread
that stepped it nor on the order).

Runs join on their first cycle (a body given to :meth:`PhysicsGate.run`, or one its
``more`` hands in between two dispatches: a refill) and leave by ending (they aligned, aborted,
timed out, or raised): the gate takes the control back whenever a run steps or
ends, so it never waits on a run that left, and a run that dies anywhere is
simply gone. No OS thread hands the interpreter to another per cycle: switching
greenlets costs about a microsecond, where a lockstep of threads paid the
interpreter lock's hand-over and the scheduler's wake-up latency per run and cycle
(measured: two runs as threads took 4 times as long as the two alone, see
``docs/batch.md``).

The dispatch: ``threads`` workers (the gate's thread and ``threads - 1``
helpers), each calling ``mj_step`` over a share of the runs; ``mj_step``
releases the GIL, so the shares run in parallel.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field

import greenlet
import mujoco

__all__ = ["PhysicsGate", "current_gate", "use_gate"]

_ACTIVE: ContextVar[PhysicsGate | None] = ContextVar("physics_gate", default=None)


def current_gate() -> PhysicsGate | None:
    """The gate worlds built now step through (``None``: they step alone)."""
    return _ACTIVE.get()


@contextmanager
def use_gate(gate: PhysicsGate | None) -> Iterator[None]:
    """Worlds built inside the block step through ``gate``."""
    token = _ACTIVE.set(gate)
    try:
        yield
    finally:
        _ACTIVE.reset(token)


@dataclass
class _Call:
    model: mujoco.MjModel
    data: mujoco.MjData
    nstep: int
    error: BaseException | None = None


@dataclass
class GateStats:
    """What a gate did."""

    dispatches: int = 0
    """Dispatches made (one per cycle of the batch)."""
    stepped: int = 0
    """Run-cycles stepped."""
    widths: dict[int, int] = field(default_factory=dict)
    """How many dispatches stepped how many runs."""
    physics_s: float = 0.0
    """Wall time in the dispatches (the physics of the runs, on all threads)."""


class PhysicsGate:
    """Runs a batch of runs, stepping the cycles of every live run in one dispatch;
    see the module doc.

    Args:
        threads: threads that share a dispatch's ``mj_step`` calls (1: the gate's
            thread alone).
    """

    def __init__(self, threads: int = 1) -> None:
        if threads < 1:
            raise ValueError("threads must be >= 1")
        self.threads = threads
        self.stats = GateStats()
        self._hub: greenlet.greenlet | None = None
        self._members: set[greenlet.greenlet] = set()
        self._helpers: list[threading.Thread] = []
        self._work: list[list[_Call]] = []
        self._work_cond = threading.Condition()
        self._work_gen = 0
        self._work_left = 0
        self._closed = False

    def run(self, bodies: Sequence[Callable[[], object]],
            more: Callable[[], Sequence[Callable[[], object]]] | None = None) -> None:
        """Run every body to its end, as a batch: a greenlet each on this thread, their
        worlds' cycles stepped together. A body's exception ends only that body (a body
        is expected to catch its own; one that escapes is dropped here).

        ``more``: called before each cycle's round (after the previous dispatch), the
        bodies that join the batch now (a refill: they run up to their first step and
        are stepped in this round's dispatch). The batch ends when no body is left and
        ``more`` gives none."""
        if self._hub is not None:
            raise RuntimeError("this gate is running a batch already")
        self._hub = greenlet.getcurrent()
        try:
            ready = [greenlet.greenlet(self._member(body)) for body in bodies]
            self._members = set(ready)
            while True:
                if more is not None:
                    joining = [greenlet.greenlet(self._member(body)) for body in more()]
                    self._members.update(joining)
                    ready += joining
                if not ready:
                    break
                calls: list[tuple[greenlet.greenlet, _Call]] = []
                for g in ready:
                    try:
                        call = g.switch()
                    except BaseException:  # the body's own end (see above)
                        call = None
                    if isinstance(call, _Call) and not g.dead:
                        calls.append((g, call))
                    else:
                        self._members.discard(g)
                if calls:
                    self._dispatch([c for _, c in calls])
                ready = [g for g, _ in calls]
        finally:
            self._hub = None
            self._members = set()
            self._close_helpers()

    def _member(self, body: Callable[[], object]) -> Callable[[], None]:
        def start() -> None:
            with use_gate(self):
                body()
        return start

    def step(self, model: mujoco.MjModel, data: mujoco.MjData, nstep: int) -> None:
        """``mj_step(model, data, nstep)``, together with the batch's other runs' cycles
        (alone when not called from a run of the batch); raises what the step raised."""
        hub = self._hub
        if hub is None or greenlet.getcurrent() not in self._members:
            mujoco.mj_step(model, data, nstep)
            return
        call = _Call(model, data, nstep)
        hub.switch(call)
        if call.error is not None:
            raise call.error

    # -- the dispatch ---------------------------------------------------------------
    def _dispatch(self, calls: list[_Call]) -> None:
        st = self.stats
        st.dispatches += 1
        st.stepped += len(calls)
        st.widths[len(calls)] = st.widths.get(len(calls), 0) + 1
        t0 = time.perf_counter()
        try:
            self._step_all(calls)
        finally:
            st.physics_s += time.perf_counter() - t0

    def _step_all(self, calls: list[_Call]) -> None:
        k = min(self.threads, len(calls))
        if k <= 1:
            _run(calls)
            return
        self._start_helpers(k - 1)
        shares = [calls[i::k] for i in range(k)]
        with self._work_cond:
            self._work = shares[1:]
            self._work_left = len(self._work)
            self._work_gen += 1
            self._work_cond.notify_all()
        _run(shares[0])
        with self._work_cond:
            while self._work_left:
                self._work_cond.wait()

    def _start_helpers(self, n: int) -> None:
        self._closed = False
        while len(self._helpers) < n:
            t = threading.Thread(target=self._helper, args=(len(self._helpers),),
                                 name=f"physics-gate-{len(self._helpers)}", daemon=True)
            self._helpers.append(t)
            t.start()

    def _helper(self, index: int) -> None:
        seen = 0
        while True:
            with self._work_cond:
                while self._work_gen == seen and not self._closed:
                    self._work_cond.wait()
                if self._closed:
                    return
                seen = self._work_gen
                share = self._work[index] if index < len(self._work) else None
            if share is None:
                continue
            _run(share)
            with self._work_cond:
                self._work_left -= 1
                self._work_cond.notify_all()

    def _close_helpers(self) -> None:
        with self._work_cond:
            self._closed = True
            self._work_cond.notify_all()
        for t in self._helpers:
            t.join()
        self._helpers = []


def _run(calls: list[_Call]) -> None:
    step = mujoco.mj_step
    for c in calls:
        try:
            step(c.model, c.data, c.nstep)
        except BaseException as exc:  # the run's own error, raised in the run
            c.error = exc
