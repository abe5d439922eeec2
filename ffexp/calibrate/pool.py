"""Rollouts in parallel: every (candidate, recording) pair of a batch on a process pool.

Each worker process reads the replay inputs once (its initializer) and then
replays whichever recordings it is handed with the candidates' overrides.
``jobs = 1`` runs in the calling process (tests; one core).

``batch > 1``: the rollouts a process is handed are stepped together, up to
``batch`` at once, as the runs of one physics gate
(:func:`~ffexp.sweeps.batch.step_together`: a greenlet each, their physics one
dispatch a cycle; ``docs/batch.md``); each
rollout is still the rollout alone, bit for bit, so the fit is the same. The
rollouts of a call are spread over the processes (``ceil(rollouts / jobs)`` a
batch, at most ``batch``).
"""

from __future__ import annotations

import math
import multiprocessing
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from pathlib import Path

from ffexp.calibrate.inputs import ReplayInput
from ffexp.calibrate.resim import Trace, rollout

_INPUTS: tuple[ReplayInput, ...] = ()
_SCENE: Path = Path()


def _init(inputs: tuple[ReplayInput, ...], scene_file: Path) -> None:
    global _INPUTS, _SCENE
    _INPUTS, _SCENE = inputs, scene_file


def _run(index: int, overrides: tuple[str, ...]) -> Trace:
    return rollout(_INPUTS[index], _SCENE, overrides)


def _run_batch(tasks: Sequence[tuple[int, tuple[str, ...]]]) -> list[Trace]:
    return stepped_together(_INPUTS, _SCENE, tasks)


def stepped_together(inputs: Sequence[ReplayInput], scene_file: Path,
                     tasks: Sequence[tuple[int, tuple[str, ...]]]) -> list[Trace]:
    """The rollouts ``tasks`` (a recording's index in ``inputs`` and the overrides) as one
    batch in this process: a run each of one gate, their physics one dispatch a cycle."""
    from ffexp.sweeps.batch import step_together

    out: list[Trace | BaseException | None] = [None] * len(tasks)

    def body(k: int) -> None:
        i, overrides = tasks[k]
        try:
            out[k] = rollout(inputs[i], scene_file, overrides)
        except BaseException as exc:  # raised in the caller, as a rollout alone raises
            out[k] = exc

    step_together([lambda k=k: body(k) for k in range(len(tasks))])  # type: ignore[misc]
    traces = []
    for t in out:
        if isinstance(t, BaseException):
            raise t
        assert t is not None
        traces.append(t)
    return traces


class Rollouts:
    """Replays recordings with candidate overrides, ``jobs`` processes at a time, each
    stepping up to ``batch`` rollouts together; a context manager."""

    def __init__(self, inputs: Sequence[ReplayInput], scene_file: Path, jobs: int = 2,
                 on_done: Callable[[int], None] | None = None, batch: int = 1) -> None:
        self.inputs = tuple(inputs)
        self.scene_file = scene_file
        self.jobs = max(1, jobs)
        self.batch = max(1, batch)
        self.on_done = on_done
        self.count = 0
        """Rollouts run so far."""
        self._pool: ProcessPoolExecutor | None = None

    def __enter__(self) -> Rollouts:
        if self.jobs > 1:
            self._pool = ProcessPoolExecutor(
                max_workers=self.jobs, mp_context=multiprocessing.get_context("spawn"),
                initializer=_init, initargs=(self.inputs, self.scene_file))
        return self

    def __exit__(self, *exc: object) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def run(self, candidates: Sequence[tuple[str, ...]],
            which: Sequence[int] | None = None) -> list[list[Trace]]:
        """Traces of the recordings ``which`` (default: all) for each candidate's overrides."""
        idx = list(range(len(self.inputs))) if which is None else list(which)
        tasks = [(i, tuple(candidates[c])) for c in range(len(candidates)) for i in idx]
        if self.batch > 1:
            traces = self._batched(tasks)
        elif self._pool is None:
            traces = []
            for i, overrides in tasks:
                traces.append(rollout(self.inputs[i], self.scene_file, overrides))
                self._done()
        else:
            futures: list[Future[Trace]] = []
            for i, overrides in tasks:
                fut = self._pool.submit(_run, i, overrides)
                fut.add_done_callback(lambda _f: self._done())
                futures.append(fut)
            traces = [fut.result() for fut in futures]
        n = len(idx)
        return [traces[c * n:(c + 1) * n] for c in range(len(candidates))]

    def _batched(self, tasks: list[tuple[int, tuple[str, ...]]]) -> list[Trace]:
        size = min(self.batch, math.ceil(len(tasks) / self.jobs)) if tasks else 1
        chunks = [tasks[k:k + size] for k in range(0, len(tasks), size)]
        if self._pool is None:
            out: list[Trace] = []
            for chunk in chunks:
                out += stepped_together(self.inputs, self.scene_file, chunk)
                self._done(len(chunk))
            return out
        futures: list[Future[list[Trace]]] = []
        for chunk in chunks:
            fut = self._pool.submit(_run_batch, chunk)
            fut.add_done_callback(lambda _f, n=len(chunk): self._done(n))  # type: ignore[misc]
            futures.append(fut)
        return [t for fut in futures for t in fut.result()]

    def _done(self, n: int = 1) -> None:
        for _ in range(n):
            self.count += 1
            if self.on_done is not None:
                self.on_done(self.count)
