"""Limit searches on the engine: :func:`ffexp.sweeps.limits.search` with runs as outcomes.

:class:`LimitSearch` evaluates a point by running it with every seed through a
:class:`~ffexp.sweeps.engine.Runner` (runs cached by id in the sweep
directory: the same search twice runs nothing the second time and gives the
same answer) and keeps every row it ran.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from ffexp import outcome
from ffexp.errors import ConfigError
from ffexp.sweeps import limits
from ffexp.sweeps.engine import Runner
from ffexp.sweeps.keys import Key
from ffexp.sweeps.plan import Target, check_keys


@dataclass
class LimitSearch:
    """One search: a protocol, one or two keys with their ranges, seeds, resolution."""

    target: Target
    keys: list[Key]
    ranges: list[tuple[float, float]]
    seeds: list[int]
    resolution: list[float]
    coarse: int = 5
    rays: int = 8
    name: str = ""
    max_breaks: int | None = None
    """A run counts as aligning only with at most this many contact breaks (None: any)."""
    rows: list[dict[str, Any]] = field(default_factory=list)
    result: limits.SearchResult | None = None

    def __post_init__(self) -> None:
        if len(self.keys) not in (1, 2) or len(self.ranges) != len(self.keys):
            raise ConfigError("--key", " ".join(k.text for k in self.keys),
                              "give one or two keys, each with its --range")
        if len(self.resolution) == 1:
            self.resolution = self.resolution * len(self.keys)
        if len(self.resolution) != len(self.keys) or any(
                not r > 0 for r in self.resolution):
            raise ConfigError("--resolution", " ".join(map(str, self.resolution)),
                              "one positive value, or one per key")
        if self.coarse < 2:
            raise ConfigError("--coarse", str(self.coarse), "must be at least 2")
        if self.max_breaks is not None and self.max_breaks < 0:
            raise ConfigError("--max-breaks", str(self.max_breaks), "must be 0 or more")
        if len(self.keys) == 2 and self.rays < 3:
            raise ConfigError("--rays", str(self.rays), "must be at least 3")
        self.name = self.name or self.target.label

    def check(self) -> None:
        """Validate both ends of every range (and the centre) before anything runs; a
        key the protocol and scene do not have is named as ``--key``'s fault."""
        corners = [[lo for lo, _ in self.ranges], [hi for _, hi in self.ranges]]
        try:
            for values in corners:
                self.target.check(self.keys, self._point(values), "--range")
        except ConfigError:
            check_keys(self.target, self.keys, {k.text: "--key" for k in self.keys})
            raise

    def _point(self, coords: Sequence[float]) -> dict[str, Any]:
        return {k.text: float(c) for k, c in zip(self.keys, coords, strict=True)}

    def segments(self) -> list[limits.Segment]:
        if len(self.keys) == 1:
            return limits.line(*self.ranges[0])
        return limits.rays(self.ranges, self.rays)

    def run(self, runner: Runner) -> limits.SearchResult:
        inputs = self.target.snapshot(runner.inputs)

        def evaluate(points: list[limits.Coords]) -> list[float]:
            jobs = [self.target.job(self.keys, self._point(p), s, runner.out_dir, inputs)
                    for p in points for s in self.seeds]
            rows = runner.run_batch(jobs)
            self.rows.extend(rows)
            n = len(self.seeds)
            return [sum(self.aligns(r) for r in rows[i * n:(i + 1) * n]) / n
                    for i in range(len(points))]

        self.result = limits.search(evaluate, self.segments(), coarse=self.coarse,
                                    resolution=self.resolution)
        return self.result

    def aligns(self, row: dict[str, Any]) -> bool:
        """The outcome the search bisects: the run's outcome (:mod:`ffexp.outcome`) is
        "aligned" and its contact did not keep breaking on the way (the paper's limits:
        no sliding below, contact breaking above); without error, and with at most
        ``max_breaks`` contact breaks when that is set. Rows without an outcome: their
        aligned flag."""
        if row.get("error") or limit_outcome(row) != outcome.ALIGNED:
            return False
        return self.max_breaks is None or int(row.get("contact_breaks") or 0) <= self.max_breaks

    def limits_rows(self) -> list[dict[str, Any]]:
        """The limits found, each with ``beyond``: the outcome on its side that does not
        align (lower limit: below it; upper: above it), the most common over seeds."""
        assert self.result is not None
        names = [k.text for k in self.keys]
        out = []
        for row in limits.describe(self.result, names):
            far = "from" if row["lo_fraction"] <= row["hi_fraction"] else "to"
            at = tuple(row[f"{n} {far}"] for n in names)
            out.append({"search": self.name, **row, "beyond": self.outcome_at(at)})
        return out

    def outcome_at(self, coords: Sequence[float]) -> str | None:
        """The most common outcome of the runs at a point (None: none ran there)."""
        said = [limit_outcome(r) for r in self.rows
                if all(r.get(k.text) == c for k, c in zip(self.keys, coords, strict=True))]
        return max(sorted(set(said)), key=said.count) if said else None

    def points(self) -> list[tuple[limits.Coords, float]]:
        assert self.result is not None
        return sorted(self.result.evaluated.items())


def limit_outcome(row: dict[str, Any]) -> str:
    """A row's outcome as the limits read it: an aligned run whose contact kept breaking
    before its seat is "contact kept breaking, then aligned"; an error is "error"."""
    if row.get("error"):
        return "error"
    said = row.get("outcome")
    if not said:
        return outcome.ALIGNED if row.get("aligned") else "not aligned"
    if said == outcome.ALIGNED and outcome.kept_breaking(
            said, int(row.get("breaks_after_transient") or 0)):
        return f"{outcome.KEPT_BREAKING_LABEL}, then aligned"
    return str(said)
