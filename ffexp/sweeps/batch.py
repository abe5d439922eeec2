"""Batches of a sweep's runs, stepped together in one process (``--executor batch:N``).

A batch is up to N runs in one worker process. Each run is exactly the code of
a run alone (:func:`~ffexp.sweeps.worker.run_one`: run, analyse, commit), as a
run of one :class:`~drivers.world.gate.PhysicsGate` (a greenlet each, on the
process's thread), so its recording and row are the same as alone; the gate
steps every live run's control cycle in one dispatch. A run leaves the batch when its run
ends (it aligned, aborted, timed out, or raised: its error is its row, as
alone), and the others go on without waiting for it.

Two executors for the sweep engine; ``submit(run_one, job)`` returns the run's own
future, as a pool's does:

- :class:`RefillExecutor` (``local:W,batch:N``): W batch processes (a fork server's
  workers, as ``local``), each keeping up to N runs live (:func:`batch_process`): a
  job goes to the process with the fewest runs as soon as one has a free slot, and
  joins its running batch between two dispatches (a refill); each run's row comes
  back when the run ends, so progress, the cache and a stop work run by run.
- :class:`BatchExecutor` (``ray[:ADDRESS],batch:N``; ``make_executor(...,
  refill=False)``): each process (or Ray task) is given a batch of at most N jobs,
  which shrinks as its runs end; the process takes its next batch when the last
  ended, and the batch's rows come back together. Jobs are grouped as they come: a
  full batch goes at once; the rest when the engine has submitted all it has
  (:meth:`BatchExecutor.flush`), spread over the free processes (a batch of
  ``ceil(jobs / free processes)``, at most N), so a few jobs still use every process.

Stopping behaves as the pool's: batch processes ignore SIGINT and SIGTERM, jobs
not yet in a batch are cancelled, the runs running finish (every run's
recording finished and its row committed); :func:`~ffexp.sweeps.executors.end_workers`
ends the processes (a second Ctrl-C), and their runs are rows of a failed worker.
"""

from __future__ import annotations

import functools
import math
import threading
from collections import deque
from collections.abc import Callable, Sequence
from concurrent.futures import Executor, Future
from typing import TYPE_CHECKING, Any, TypeVar

from ffexp.sweeps import worker
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


def step_together(bodies: Sequence[Callable[[], object]], threads: int = 1) -> None:
    """Run ``bodies`` (each a run of the simulated world, e.g. a calibration's rollout)
    to their ends as one batch of a :class:`~drivers.world.gate.PhysicsGate`: a greenlet
    each, their physics one dispatch a cycle; a body is expected to catch its own
    exceptions."""
    from drivers.world.gate import PhysicsGate

    PhysicsGate(threads).run(bodies)


class _RunsExecutor(Executor):
    """What both batch executors share: ``run_one`` jobs queued under one lock (each with
    its own future), anything else submitted to ``pool`` as it is, and the pool's
    processes for :func:`~ffexp.sweeps.executors.end_workers`."""

    def __init__(self, pool: Executor, processes: int, batch: int,
                 threads: int = 1) -> None:
        self._pool = pool
        self.processes = max(1, processes)
        self.batch = max(1, batch)
        self.threads = max(1, threads)
        self._cond = threading.Condition()
        self._pending: deque[tuple[Job, Future[dict[str, Any]]]] = deque()
        self._shutdown = False

    # the pool's processes, for end_workers
    @property
    def _processes(self) -> Any:
        return getattr(self._pool, "_processes", None)

    @property
    def _executor_manager_thread(self) -> Any:
        return getattr(self._pool, "_executor_manager_thread", None)

    def submit(self, fn: Callable[..., T], /, *args: Any, **kwargs: Any) -> Future[T]:
        if fn is not worker.run_one or kwargs or len(args) != 1:
            return self._pool.submit(fn, *args, **kwargs)
        fut: Future[dict[str, Any]] = Future()
        with self._cond:
            if self._shutdown:
                raise RuntimeError("cannot schedule new futures after shutdown")
            self._pending.append((args[0], fut))
            failed = self._queued()
        _fail(failed)
        return fut  # type: ignore[return-value]  # run_one's future

    def _queued(self) -> list[tuple[Future[Any], BaseException]]:
        """A job was queued (the lock held): send what can go; the futures to fail."""
        raise NotImplementedError

    def _close_queue(self, cancel_futures: bool) -> list[Future[dict[str, Any]]]:
        """Take no new jobs (the lock held); with ``cancel_futures`` the queued jobs leave
        the queue: their futures, for the caller to cancel outside the lock."""
        self._shutdown = True
        if not cancel_futures:
            return []
        dropped = [fut for _, fut in self._pending]
        self._pending.clear()
        return dropped


class BatchExecutor(_RunsExecutor):
    """Runs ``run_one`` jobs in batches of at most ``batch`` on ``processes`` processes
    (``pool``: a process pool of them, or Ray's tasks, ``processes`` the cluster's CPUs).

    Anything else submitted goes to the pool as it is (one call in one process).
    """

    def __init__(self, pool: Executor, processes: int, batch: int,
                 threads: int = 1) -> None:
        super().__init__(pool, processes, batch, threads)
        self._inflight = 0

    def _queued(self) -> list[tuple[Future[Any], BaseException]]:
        return self._dispatch(full_only=True) if len(self._pending) >= self.batch else []

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
            dropped = self._close_queue(cancel_futures)
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


def batch_process(conn_blob: bytes, size: int, threads: int = 1) -> int:
    """A batch process's loop (``local:W,batch:N``, :class:`RefillExecutor`): up to
    ``size`` runs live in one :class:`~drivers.world.gate.PhysicsGate`; a job received
    while a slot is free joins the running batch between two dispatches (a refill), and
    each run's outcome goes back as the run ends.

    ``conn_blob``: the pickled end of a pipe to the executor. Received: ``(key, job)``,
    or ``None`` (no more jobs: finish the live runs and return). Sent: ``(key, kind,
    value)`` per run (``kind`` as :data:`BatchOutcome`'s). Returns the runs run.
    """
    import pickle

    from drivers.world.gate import PhysicsGate

    conn = pickle.loads(conn_blob)
    gate = PhysicsGate(threads)
    state = {"live": 0, "ran": 0, "stop": False}

    def body(key: int, job: Job) -> None:
        try:
            out: BatchOutcome = ("row", run_one(job))
        except BaseException as exc:  # reported as the run's failure
            out = ("failed", f"{type(exc).__name__}: {exc}".splitlines()[0])
        state["live"] -= 1
        state["ran"] += 1
        conn.send((key, *out))

    def receive(block: bool) -> Callable[[], None] | None:
        if state["stop"] or not (block or conn.poll(0)):
            return None
        try:
            msg = conn.recv()
        except (EOFError, OSError):  # the executor is gone: finish what runs
            msg = None
        if msg is None:
            state["stop"] = True
            return None
        state["live"] += 1
        return functools.partial(body, *msg)

    def more() -> list[Callable[[], None]]:
        joining: list[Callable[[], None]] = []
        while state["live"] < size and (nxt := receive(block=False)) is not None:
            joining.append(nxt)
        return joining

    try:
        while (first := receive(block=True)) is not None:
            gate.run([first], more=more)
    finally:
        conn.close()
    return state["ran"]


class _Slot:
    """One batch process's task of a :class:`RefillExecutor` and its runs."""

    def __init__(self, conn: Any, task: Future[int]) -> None:
        self.conn = conn
        self.task = task
        self.live: dict[int, Future[dict[str, Any]]] = {}
        self.ended = 0  # runs whose rows were read but not yet resolved: still no free slot
        self.ending = False  # told that no more jobs come: it ends when its runs have
        self.readable = True  # its pipe not at its end yet


class RefillExecutor(_RunsExecutor):
    """Runs ``run_one`` jobs in batch processes that each keep up to ``batch`` runs
    live (``pool``: a process pool of ``processes`` processes): a job goes to the batch
    process with the fewest runs as soon as it has a free slot (a process without a
    batch gets one), joining its running batch between two dispatches, and each run's
    row comes back as the run ends (its future resolved then).

    A batch process's task ends when it is told no more jobs come (none queued, its last
    run ended), freeing the process; anything else submitted goes to the pool as it is.
    """

    def __init__(self, pool: Executor, processes: int, batch: int,
                 threads: int = 1) -> None:
        super().__init__(pool, processes, batch, threads)
        self._slots: list[_Slot | None] = [None] * self.processes
        self._keys = 0
        self._broken: BaseException | None = None
        self._collector: threading.Thread | None = None
        self._wake_r: Any = None
        self._wake_w: Any = None

    def _queued(self) -> list[tuple[Future[Any], BaseException]]:
        self._start_collector()
        return self._dispatch()

    def flush(self) -> None:
        """Jobs go as they come: nothing waits for a flush."""

    # -- the parent's side (the lock held where said) --------------------------------
    def _start_collector(self) -> None:
        if self._collector is None:
            import multiprocessing

            self._wake_r, self._wake_w = multiprocessing.Pipe(duplex=False)
            self._collector = threading.Thread(target=self._collect, daemon=True,
                                               name="batch-collector")
            self._collector.start()

    def _dispatch(self) -> list[tuple[Future[Any], BaseException]]:
        """Queued jobs to free slots (the lock held); returns the futures to fail outside
        the lock (the pool refused work: a process of it died, or it was shut down)."""
        while self._pending:
            if self._broken is not None:
                return self._fail_pending(self._broken)
            free = [(len(s.live) + s.ended, w) for w, s in enumerate(self._slots)
                    if s is not None and not s.ending and len(s.live) + s.ended < self.batch]
            idle = [w for w, s in enumerate(self._slots) if s is None]
            if idle and (not free or min(free)[0] > 0):
                try:
                    self._start_slot(idle[0])
                except RuntimeError as exc:  # BrokenProcessPool, or the pool was shut down
                    self._broken = exc
                    return self._fail_pending(exc)
                continue
            if not free:
                break
            slot = self._slots[min(free)[1]]
            assert slot is not None
            job, fut = self._pending.popleft()
            if not fut.set_running_or_notify_cancel():  # cancelled while queued
                continue
            self._keys += 1
            try:
                slot.conn.send((self._keys, job))
            except OSError as exc:  # the process died: its end fails this run
                self._broken = exc
                return [(fut, exc), *self._fail_pending(exc)]
            slot.live[self._keys] = fut
        return []

    def _fail_pending(self, exc: BaseException) -> list[tuple[Future[Any], BaseException]]:
        rest = [f for _, f in self._pending if f.set_running_or_notify_cancel()]
        self._pending.clear()
        return [(f, exc) for f in rest]

    def _start_slot(self, w: int) -> None:
        import multiprocessing
        from multiprocessing.reduction import ForkingPickler

        mine, theirs = multiprocessing.Pipe()
        blob = bytes(ForkingPickler.dumps(theirs))  # its descriptor shared until taken
        theirs.close()
        task = self._pool.submit(batch_process, blob, self.batch, self.threads)
        self._slots[w] = _Slot(mine, task)
        self._wake()  # the collector listens to its pipe from now on
        task.add_done_callback(lambda _t: self._wake())

    def _wake(self) -> None:
        with self._cond:
            if self._wake_w is not None:
                self._wake_w.send_bytes(b"w")

    def _end_idle(self) -> None:
        """Slots with no run and no job queued are told no more jobs come (the lock
        held); so is every slot once shut down and nothing is queued."""
        if self._pending:
            return
        for s in self._slots:
            if s is not None and not s.ending and not s.live:
                s.ending = True
                try:
                    s.conn.send(None)
                except OSError:
                    pass

    def _collect(self) -> None:
        """The collector thread: rows as the runs end, slots whose task ended freed."""
        from multiprocessing.connection import wait as wait_for

        while True:
            with self._cond:
                conns = {s.conn: s for s in self._slots if s is not None and s.readable}
                if self._shutdown and not conns and all(s is None for s in self._slots):
                    self._cond.notify_all()
                    return
            ready = wait_for([*conns, self._wake_r])
            done: list[tuple[Future[Any], BatchOutcome | BaseException]] = []
            for conn in ready:
                if conn is self._wake_r:
                    self._woken()
                    continue
                done += self._read(conns[conn])
            with self._cond:
                for w, s in enumerate(self._slots):
                    if s is not None and s.task.done():
                        done += self._drain(s)
                        self._slots[w] = None
            # the rows first (outside the lock: the engine's callbacks take its own), so a
            # stop they ask for cancels the queued jobs before the freed slots take them
            for fut, outcome in done:
                if isinstance(outcome, BaseException):
                    fut.set_exception(outcome)
                elif outcome[0] == "row":
                    fut.set_result(outcome[1])
                else:
                    fut.set_exception(RuntimeError(outcome[1]))
            with self._cond:  # the rows resolved: their slots are free now
                for s in self._slots:
                    if s is not None:
                        s.ended = 0
                failed = self._dispatch()
                self._end_idle()
                self._cond.notify_all()
            _fail(failed)

    def _woken(self) -> None:
        """Empty the collector's wake-up pipe."""
        while self._wake_r.poll(0):
            self._wake_r.recv_bytes()

    def _read(self, s: _Slot) -> list[tuple[Future[Any], BatchOutcome | BaseException]]:
        """The runs ended that ``s``'s pipe has to say (all it has, without blocking)."""
        out: list[tuple[Future[Any], BatchOutcome | BaseException]] = []
        try:
            while s.readable and s.conn.poll(0):
                key, kind, value = s.conn.recv()
                with self._cond:
                    fut = s.live.pop(key)
                    s.ended += 1  # its slot freed once its row is resolved (a stop first)
                out.append((fut, (kind, value)))
        except (EOFError, OSError):
            s.readable = False
        return out

    def _drain(self, s: _Slot) -> list[tuple[Future[Any], BatchOutcome | BaseException]]:
        """A slot whose task ended (the lock held): what its pipe still holds, then its
        runs still live fail with the task's error (its process died)."""
        out = self._read(s)
        s.conn.close()
        exc = None if s.task.cancelled() else s.task.exception()
        if exc is not None:
            from concurrent.futures.process import BrokenProcessPool

            if isinstance(exc, BrokenProcessPool):
                self._broken = exc
        lost = exc or RuntimeError("the batch process ended before its runs")
        out += [(fut, lost) for fut in s.live.values()]
        s.live.clear()
        return out

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        with self._cond:
            dropped = self._close_queue(cancel_futures)
            self._end_idle()
            collector = self._collector
            if self._wake_w is not None:
                self._wake_w.send_bytes(b"w")
        for fut in dropped:
            fut.cancel()
        if wait and collector is not None:  # the jobs submitted run first, as a pool's do
            collector.join()
        self._pool.shutdown(wait=wait, cancel_futures=cancel_futures)
