"""One call at a time in a worker thread, handed over and waited for: :class:`Worker`.

The run log hands each cycle's recording to a worker (:class:`~ffexp.runlog.RunLog`
with ``writer_thread``) so that its encoding runs while the loop's thread is inside
a call that releases the GIL (the physics of the next cycle), not after it. The
worker's burst ends in a blocking ``get``, so it never holds the GIL for a switch
interval against the loop (the GIL convoy of a thread that keeps computing).

Exactly one call is in flight: :meth:`Worker.post` first waits for the previous
one, and :meth:`Worker.wait` is the caller's point of synchronisation: after it,
the worker touches nothing, and an exception the call raised is raised here, in
the caller's thread (the same exception object, its traceback from the worker).
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable
from typing import Any

__all__ = ["Worker"]

_STOP = None


class Worker:
    """A daemon thread that runs posted calls one at a time (module docstring).

    Args:
        name: the thread's name.
    """

    def __init__(self, name: str) -> None:
        self._todo: queue.SimpleQueue[tuple[Callable[..., object], tuple[Any, ...]] | None] = (
            queue.SimpleQueue())
        self._done: queue.SimpleQueue[BaseException | None] = queue.SimpleQueue()
        self.busy = False
        """Whether a posted call may still be running (until :meth:`wait`)."""
        self._closed = False
        self._thread = threading.Thread(target=self._work, name=name, daemon=True)
        self._thread.start()

    def post(self, fn: Callable[..., object], args: tuple[Any, ...]) -> None:
        """Run ``fn(*args)`` in the worker; the previous call is waited for first (and
        its exception, if any, raised here instead). ``args`` must not change until the
        next :meth:`wait` (or :meth:`post`)."""
        if self.busy:
            self.wait()
        if self._closed:
            raise RuntimeError("worker closed")
        self.busy = True
        self._todo.put((fn, args))

    def wait(self) -> None:
        """Wait until the posted call has returned; raise its exception, if it raised."""
        if not self.busy:
            return
        error = self._done.get()  # busy until it came (an interrupted get: still busy)
        self.busy = False
        if error is not None:
            try:
                raise error
            finally:
                error = None  # no cycle through the traceback's frame

    def close(self) -> None:
        """Wait for the posted call (raising its exception), then end the thread;
        idempotent. The thread ends even when the call raised."""
        if self._closed:
            return
        try:
            self.wait()
        finally:
            self._closed = True
            self._todo.put(_STOP)
            self._thread.join()

    def _work(self) -> None:
        get, put = self._todo.get, self._done.put
        while True:
            item = get()
            if item is None:
                return
            fn, args = item
            try:
                fn(*args)
            except BaseException as exc:  # handed to the caller's thread
                put(exc)
            else:
                put(None)
            del item, fn, args  # nothing of the call kept while waiting
