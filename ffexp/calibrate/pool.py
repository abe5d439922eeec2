"""Rollouts in parallel: every (candidate, recording) pair of a batch on a process pool.

Each worker process reads the replay inputs once (its initializer) and then
replays whichever recording it is handed with the candidate's overrides.
``jobs = 1`` runs in the calling process (tests; one core).
"""

from __future__ import annotations

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


class Rollouts:
    """Replays recordings with candidate overrides, ``jobs`` at a time; a context manager."""

    def __init__(self, inputs: Sequence[ReplayInput], scene_file: Path, jobs: int = 2,
                 on_done: Callable[[int], None] | None = None) -> None:
        self.inputs = tuple(inputs)
        self.scene_file = scene_file
        self.jobs = max(1, jobs)
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
        tasks = [(c, i) for c in range(len(candidates)) for i in idx]
        out: list[list[Trace | None]] = [[None] * len(idx) for _ in candidates]
        if self._pool is None:
            for c, i in tasks:
                out[c][idx.index(i)] = rollout(self.inputs[i], self.scene_file, candidates[c])
                self._done()
        else:
            futures: list[tuple[int, int, Future[Trace]]] = []
            for c, i in tasks:
                fut = self._pool.submit(_run, i, candidates[c])
                fut.add_done_callback(lambda _f: self._done())
                futures.append((c, idx.index(i), fut))
            for c, j, fut in futures:
                out[c][j] = fut.result()
        return [[t for t in row if t is not None] for row in out]

    def _done(self) -> None:
        self.count += 1
        if self.on_done is not None:
            self.on_done(self.count)
