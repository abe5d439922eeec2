"""``--executor``: a process pool on this machine, or Ray, both as a
:class:`concurrent.futures.Executor`.

- ``local`` / ``local:N``: :class:`~concurrent.futures.ProcessPoolExecutor`
  with N workers (default: the CPUs this process may use), forked by a
  ``forkserver`` that imported the simulator once (no fork of this process,
  which runs threads; no import per worker).
- ``batch:N`` / ``local:W,batch:N``: W processes (default: the CPUs this process may
  use), each stepping up to N runs together in lockstep, their physics in one
  dispatch a cycle, a queued job joining a process's batch as soon as one of its runs
  ends (:mod:`ffexp.sweeps.batch`); the same rows as ``local``. Its ``workers`` (the
  runs at once, the progress bar's slots) is ``W * N``.
- ``ray[:ADDRESS],batch:N``: the batches of ``batch:N`` as Ray tasks (one CPU each):
  each task steps a batch of up to N runs on a worker of the cluster, as many
  batches at once as the cluster has CPUs.
- ``ray``: as Ray's own ``ray.init()``: join the running cluster (``RAY_ADDRESS``,
  else the latest ``ray start`` on this machine), or else start a Ray instance
  here for this sweep; ``ray:auto`` only joins (an error when no cluster runs,
  as ``ray.init(address="auto")``); ``ray:HOST:PORT`` joins a cluster's GCS
  address; ``ray://HOST:PORT`` a Ray client server; ``ray:local`` always starts a
  Ray instance here. A process that already called ``ray.init`` is reused.

Ray is optional (``pip install -e ".[ray]"``) and imported only when asked for.
"""

from __future__ import annotations

import logging
import os
import socket
from collections.abc import Callable
from concurrent.futures import Executor, Future, ProcessPoolExecutor
from dataclasses import dataclass
from typing import Any, TypeVar

from ffexp.errors import ConfigError

T = TypeVar("T")
OPTION = "--executor"
#: Imported once by the fork server; every worker forked from it has them (a worker
#: that imported them itself took seconds on a loaded two-core machine).
PRELOAD = ("ffexp.sweeps.worker", "ffexp.sweeps.batch", "ffexp.experiment", "ffexp.analysis",
           "ffexp.recording", "ffexp.estimation.kernels", "drivers.world.gate",
           "drivers.world.world", "drivers.fri.emulate.lockstep")
#: Seconds to wait for a TCP answer from a Ray address before calling it unreachable.
CONNECT_TIMEOUT_S = 3.0


@dataclass(frozen=True)
class ExecutorSpec:
    kind: str
    """``local``, ``batch`` or ``ray``."""
    workers: int = 0
    """Runs at once (``batch``: processes times runs per batch)."""
    address: str = ""
    """``ray``, or ``batch`` over Ray (``over``): the Ray address (empty: Ray's default)."""
    over: str = "local"
    """``batch``: where the batches run, ``local`` (a process pool) or ``ray``."""
    processes: int = 0
    """``batch``: the batch processes."""
    batch: int = 0
    """``batch``: runs stepped together in one process, at most."""

    @property
    def label(self) -> str:
        if self.kind == "local":
            return f"local:{self.workers}"
        ray = f"ray:{self.address}" if self.address else "ray"
        if self.kind == "batch":
            where = ray if self.over == "ray" else f"local:{self.processes}"
            return f"{where},batch:{self.batch}"
        return ray


def available_cpus() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


def _count(text: str, rest: str, what: str) -> int:
    try:
        n = int(rest)
    except ValueError:
        n = 0
    if n < 1:
        raise ConfigError(OPTION, text, f"expected {what} >= 1")
    return n


def parse_executor(text: str) -> ExecutorSpec:
    """``local[:N]``, ``[local[:W],]batch:N``, ``ray[:ADDRESS]`` or
    ``ray[:ADDRESS],batch:N``; anything else is a ConfigError (exit 2)."""
    first, comma, second = text.strip().partition(",")
    if comma or first.startswith("batch"):
        where, batch = (first.strip(), second) if comma else ("local", first)
        kind, _, rest = batch.strip().partition(":")
        lkind, _, lrest = where.partition(":")
        if kind != "batch" or lkind not in ("local", "ray") or not rest:
            raise ConfigError(OPTION, text, "expected batch:N, local[:WORKERS],batch:N or "
                              "ray[:ADDRESS],batch:N")
        n = _count(text, rest, "batch:N with N runs per batch,")
        if lkind == "ray":  # the cluster's CPUs decide how many batches run at once
            return ExecutorSpec("batch", 0, address=_ray_spec(text, where).address,
                                over="ray", batch=n)
        w = _count(text, lrest, "local:W with W workers,") if lrest else available_cpus()
        return ExecutorSpec("batch", w * n, processes=w, batch=n)
    return _ray_spec(text, text.strip()) if text.strip().startswith("ray") \
        else _local_spec(text)


def _local_spec(text: str) -> ExecutorSpec:
    kind, _, rest = text.strip().partition(":")
    if kind == "local":
        if not rest:
            return ExecutorSpec("local", available_cpus())
        try:
            n = int(rest)
        except ValueError:
            n = 0
        if n < 1:
            raise ConfigError(OPTION, text, "expected local or local:N with N >= 1 workers")
        return ExecutorSpec("local", n)
    raise ConfigError(OPTION, text, "expected local[:WORKERS], [local[:WORKERS],]batch:N, "
                      "ray[:ADDRESS] or ray[:ADDRESS],batch:N")


def _ray_spec(text: str, ray: str) -> ExecutorSpec:
    """``ray[:ADDRESS]`` (``text``: the whole option's value, for the error)."""
    kind, _, rest = ray.partition(":")
    if kind == "ray":
        if not rest:
            return ExecutorSpec("ray", address="")  # join a running cluster, else start one
        address = rest
        if address not in ("auto", "local") and not address.startswith("//"):
            host, sep, port = address.rpartition(":")
            if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
                raise ConfigError(OPTION, text, "expected ray, ray:auto, ray:local, "
                                  "ray:HOST:PORT or ray://HOST:PORT")
        return ExecutorSpec("ray", address=("ray:" + address) if address.startswith("//")
                            else address)
    raise ConfigError(OPTION, text, "expected local[:WORKERS], [local[:WORKERS],]batch:N, "
                      "ray[:ADDRESS] or ray[:ADDRESS],batch:N")


def make_executor(spec: ExecutorSpec, refill: bool = True) -> tuple[Executor, int]:
    """The executor and how many runs it runs at once.

    ``refill`` (``local:W,batch:N``): a batch process keeps N runs live, a queued job
    joining its running batch as a run ends (:class:`~ffexp.sweeps.batch.RefillExecutor`);
    ``False``: each process takes a batch of up to N jobs and the batch shrinks as its
    runs end (:class:`~ffexp.sweeps.batch.BatchExecutor`, as on Ray).

    Raises:
        ConfigError: Ray is not installed, or its address does not answer.
    """
    if spec.kind == "batch" and spec.over == "ray":
        from ffexp.sweeps.batch import BatchExecutor

        ray = RayExecutor.connect(spec.address)  # a batch a task, one CPU each
        return BatchExecutor(ray, ray.slots, spec.batch, 1), ray.slots * spec.batch
    if spec.kind in ("local", "batch"):
        import multiprocessing

        ctx = multiprocessing.get_context("forkserver")
        start_forkserver()
        processes = spec.processes if spec.kind == "batch" else spec.workers
        pool = ProcessPoolExecutor(max_workers=processes, mp_context=ctx,
                                   initializer=init_worker)
        if spec.kind == "local":
            return pool, spec.workers
        from ffexp.sweeps.batch import BatchExecutor, RefillExecutor

        # the CPUs the processes leave share each batch's physics dispatch
        threads = max(1, available_cpus() // processes)
        kind = RefillExecutor if refill else BatchExecutor
        return kind(pool, processes, spec.batch, threads), spec.workers
    ex = RayExecutor.connect(spec.address)
    return ex, ex.slots


def _check_reachable(address: str) -> None:
    """A ``HOST:PORT`` that does not accept a TCP connection is unreachable."""
    target = address.removeprefix("ray://")
    host, _, port = target.rpartition(":")
    try:
        with socket.create_connection((host, int(port)), timeout=CONNECT_TIMEOUT_S):
            pass
    except (OSError, ValueError) as exc:
        reason = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
        raise ConfigError(OPTION, f"ray:{address}", f"Ray is not reachable there: {reason}") \
            from None


class RayExecutor(Executor):
    """An Executor over Ray remote functions: ``submit`` runs ``fn`` as a Ray task
    (one CPU each) and returns the task's :class:`~concurrent.futures.Future`."""

    def __init__(self, ray: Any, started_here: bool) -> None:
        self._ray = ray
        self._started_here = started_here
        self._remote: dict[Callable[..., Any], Any] = {}
        self._refs: list[Any] = []
        self.slots = max(1, int(ray.cluster_resources().get("CPU", 1)))

    @classmethod
    def connect(cls, address: str) -> RayExecutor:
        try:
            import ray
        except ImportError:
            raise ConfigError(OPTION, f"ray:{address}",
                              'Ray is not installed (pip install -e ".[ray]")') from None
        if ray.is_initialized():
            return cls(ray, started_here=False)
        option_value = f"ray:{address}" if address else "ray"
        if address not in ("", "auto", "local"):
            _check_reachable(address)
        quiet: dict[str, Any] = {"logging_level": logging.ERROR, "log_to_driver": False}
        try:
            if address == "local":
                ray.init(num_cpus=available_cpus(), include_dashboard=False, **quiet)
            elif address == "":  # Ray's convention: join the running cluster, else start one
                ray.init(**quiet)
            else:
                ray.init(address=address, **quiet)
        except (ConnectionError, RuntimeError, ValueError) as exc:
            msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            if address == "auto" and isinstance(exc, ConnectionError):
                msg = ("no running Ray cluster to join (RAY_ADDRESS unset, no `ray start` "
                       "on this machine); start one with `ray start --head`, or give "
                       "--executor ray to start one here")
            raise ConfigError(OPTION, option_value, f"cannot connect to Ray: {msg}") from None
        return cls(ray, started_here=True)

    def submit(self, fn: Callable[..., T], /, *args: Any, **kwargs: Any) -> Future[T]:
        remote = self._remote.get(fn)
        if remote is None:
            remote = self._ray.remote(num_cpus=1, max_retries=0)(fn)
            self._remote[fn] = remote
        ref = remote.remote(*args, **kwargs)
        self._refs.append(ref)
        future: Future[T] = ref.future()
        return future

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        if cancel_futures:
            for ref in self._refs:
                try:
                    self._ray.cancel(ref, force=True)
                except Exception:
                    pass
        self._refs.clear()
        if self._started_here:
            self._ray.shutdown()


def end_workers(executor: Executor) -> None:
    """Stop the running runs now (a second Ctrl-C): end a pool's worker processes (with
    SIGKILL: they ignore SIGINT and SIGTERM, see :func:`init_worker`)."""
    processes = getattr(executor, "_processes", None) or {}
    # taken before shutdown, which forgets it (a pool's shutdown sets it to None)
    manager = getattr(executor, "_executor_manager_thread", None)
    for proc in list(processes.values()):
        proc.kill()
    executor.shutdown(wait=False, cancel_futures=True)
    # The pool's manager thread sees its workers gone, settles every run's future (each
    # ended or cancelled) and closes its wake-up pipe; let it finish before the
    # interpreter's exit hook writes to that pipe: on Python 3.11 the two race, and the
    # loser prints "OSError: Bad file descriptor". Not bounded: the exit hook itself
    # joins the thread without a bound (concurrent.futures.process._python_exit), and a
    # bound would be a race again on a loaded machine.
    if manager is not None:
        manager.join()


def start_forkserver() -> None:
    """Start the pool's fork server (if not yet), with its preloaded modules and SIGTERM
    ignored, which it and every worker forked from it keep: a ``kill -TERM`` of the whole
    process group (or cgroup, as a service manager sends it) leaves them to the sweep,
    which stops as for Ctrl-C. Only the main thread may change a handler: from another
    thread the server starts as it is (its workers still ignore SIGTERM,
    :func:`init_worker`)."""
    import multiprocessing
    import signal
    import threading
    from multiprocessing import forkserver

    multiprocessing.get_context("forkserver").set_forkserver_preload(list(PRELOAD))
    if threading.current_thread() is not threading.main_thread():
        forkserver.ensure_running()
        return
    old = signal.signal(signal.SIGTERM, signal.SIG_IGN)  # an ignored signal stays so in exec
    try:
        forkserver.ensure_running()
    finally:
        signal.signal(signal.SIGTERM, old)


def init_worker() -> None:
    """A pool worker ignores SIGINT and SIGTERM (a terminal's Ctrl-C and a
    ``kill -TERM`` of the process group reach it too): the sweep decides, letting the
    running runs finish, or ending the workers on a second signal; a run a signal
    ended is "stopped", never a failed run."""
    import signal

    from ffexp.sweeps.worker import worker_init

    worker_init()
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
