"""Batches of a sweep's runs, stepped together in one process (``--executor batch:N``).

A batch is up to N runs in one worker process. Each run is exactly the code of
a run alone (:func:`~ffexp.sweeps.worker.run_one`: run, analyse, commit), as a
run of one :class:`~drivers.world.gate.PhysicsGate` (a greenlet each, on the
process's thread), so its recording and row are the same as alone; the gate
steps every live run's control cycle in one dispatch. A run leaves the batch when its run
ends (it aligned, aborted, timed out, or raised: its error is its row, as
alone), and the others go on without waiting for it.

:class:`BatchExecutor` is the sweep engine's executor for it: a process pool of
W batch processes (a fork server's workers, as ``local``), each given batches of
at most N runs; ``submit(run_one, job)`` returns the run's own future, as the
pool's does. Jobs are grouped as they come: a full batch goes at once; the rest
when the engine has submitted all it has (:meth:`BatchExecutor.flush`), spread
over the free processes (a batch of ``ceil(jobs / free processes)``, at most N),
so a few jobs still use every process.

Stopping behaves as the pool's: batch processes ignore SIGINT and SIGTERM, jobs
not yet in a batch are cancelled, the batches running finish (every run's
recording finished and its row committed); :func:`~ffexp.sweeps.executors.end_workers`
ends the processes (a second Ctrl-C).
"""

from __future__ import annotations

import functools
import math
import threading
from collections import deque
from collections.abc import Callable
from concurrent.futures import Executor, Future
from typing import TYPE_CHECKING, Any, TypeVar

from ffexp.sweeps.worker import Job, run_one

if TYPE_CHECKING:
    from drivers.world.gate import PhysicsGate

T = TypeVar("T")

#: A run's outcome from a batch process: ("row", row) or ("failed", error text) when
#: its thread ended with an exception run_one does not turn into a row.
BatchOutcome = tuple[str, Any]


def run_batch(jobs: tuple[Job, ...], threads: int = 1,
              gate: PhysicsGate | None = None) -> list[BatchOutcome]:
    """Run ``jobs`` together in this process: each :func:`run_one` as a run of one
    :class:`~drivers.world.gate.PhysicsGate` (their physics one dispatch a cycle).

    ``threads``: the threads that share each cycle's physics dispatch (``gate``: the
    gate to use instead, its statistics kept). Returns each job's outcome, in order.
    """
    from drivers.world.gate import PhysicsGate

    out: list[BatchOutcome] = [("failed", "the run did not end")] * len(jobs)

    def body(i: int, job: Job) -> None:
        try:
            out[i] = ("row", run_one(job))
        except BaseException as exc:  # reported as the run's failure
            out[i] = ("failed", f"{type(exc).__name__}: {exc}".splitlines()[0])

    gate = gate or PhysicsGate(threads)
    gate.run([functools.partial(body, i, job) for i, job in enumerate(jobs)])
    return out


class BatchExecutor(Executor):
    """Runs ``run_one`` jobs in batches of at most ``batch`` on ``processes`` processes
    (``pool``: a process pool of them, or Ray's tasks, ``processes`` the cluster's CPUs).

    Anything else submitted goes to the pool as it is (one call in one process).
    """

    def __init__(self, pool: Executor, processes: int, batch: int,
                 threads: int = 1) -> None:
        self._pool = pool
        self.processes = max(1, processes)
        self.batch = max(1, batch)
        self.threads = max(1, threads)
        self._cond = threading.Condition()
        self._pending: deque[tuple[Job, Future[dict[str, Any]]]] = deque()
        self._inflight = 0
        self._shutdown = False

    # the pool's processes, for end_workers
    @property
    def _processes(self) -> Any:
        return getattr(self._pool, "_processes", None)

    @property
    def _executor_manager_thread(self) -> Any:
        return getattr(self._pool, "_executor_manager_thread", None)

    def submit(self, fn: Callable[..., T], /, *args: Any, **kwargs: Any) -> Future[T]:
        if fn is not run_one or kwargs or len(args) != 1:
            return self._pool.submit(fn, *args, **kwargs)
        fut: Future[dict[str, Any]] = Future()
        with self._cond:
            if self._shutdown:
                raise RuntimeError("cannot schedule new futures after shutdown")
            self._pending.append((args[0], fut))
            failed = self._dispatch(full_only=True) if len(self._pending) >= self.batch else []
        _fail(failed)
        return fut  # type: ignore[return-value]  # run_one's future

    def flush(self) -> None:
        """Send the jobs submitted so far (the engine submitted all it has for now)."""
        with self._cond:
            failed = self._dispatch(full_only=False)
        _fail(failed)

    def _dispatch(self, full_only: bool) -> list[tuple[Future[Any], BaseException]]:
        """Batches to the free processes (the lock held). Returns the futures to fail
        (outside the lock: their callbacks take the engine's) when the pool refuses work
        (a process of it died, or it was shut down): the jobs taken and all still
        queued, as a broken pool fails its own."""
        while self._inflight < self.processes and self._pending:
            free = self.processes - self._inflight
            size = min(self.batch, math.ceil(len(self._pending) / free))
            if full_only and size < self.batch:
                break
            taken: list[tuple[Job, Future[dict[str, Any]]]] = []
            while self._pending and len(taken) < size:
                job, fut = self._pending.popleft()
                if fut.set_running_or_notify_cancel():  # False: cancelled while queued
                    taken.append((job, fut))
            if not taken:
                continue
            try:
                chunk = self._pool.submit(run_batch, tuple(j for j, _ in taken), self.threads)
            except RuntimeError as exc:  # BrokenProcessPool, or the pool was shut down
                rest = [f for _, f in self._pending if f.set_running_or_notify_cancel()]
                self._pending.clear()
                return [(f, exc) for f in [*(f for _, f in taken), *rest]]
            self._inflight += 1
            chunk.add_done_callback(functools.partial(self._batch_done, taken=taken))
        return []

    def _batch_done(self, chunk: Future[list[BatchOutcome]],
                    taken: list[tuple[Job, Future[dict[str, Any]]]]) -> None:
        exc = None if chunk.cancelled() else chunk.exception()
        if chunk.cancelled():
            exc = RuntimeError("the batch was cancelled")
        for k, (_, fut) in enumerate(taken):
            if exc is not None:
                fut.set_exception(exc)
                continue
            kind, value = chunk.result()[k]
            if kind == "row":
                fut.set_result(value)
            else:
                fut.set_exception(RuntimeError(value))
        with self._cond:
            self._inflight -= 1
            failed = self._dispatch(full_only=False)
            self._cond.notify_all()
        _fail(failed)

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        with self._cond:
            self._shutdown = True
            dropped = [fut for _, fut in self._pending] if cancel_futures else []
            if cancel_futures:
                self._pending.clear()
        for fut in dropped:
            fut.cancel()
        if wait:  # the jobs submitted run first, as a pool's do
            with self._cond:
                failed = self._dispatch(full_only=False)
            _fail(failed)
            with self._cond:
                while self._inflight:
                    self._cond.wait()
        self._pool.shutdown(wait=wait, cancel_futures=cancel_futures)


def _fail(failed: list[tuple[Future[Any], BaseException]]) -> None:
    for fut, exc in failed:
        fut.set_exception(exc)
