"""``ffexp limits``: where a run stops aligning, by bisection from a coarse grid.

The search is pure (:func:`search`): it asks an ``evaluate`` function for the
aligned fraction (over seeds) at batches of points and never looks at how
they are computed, so it is tested on synthetic outcome functions. One key:
a coarse grid over ``[LO, HI]``, then bisection in every bracket where the
verdict changes, to the resolution. Two keys: the same along rays from the
centre of the box (every ray bisected at once). A point "aligns" when more
than half of its seeds align.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

Coords = tuple[float, ...]
Evaluate = Callable[[list[Coords]], list[float]]
#: A point aligns when its aligned fraction (over seeds) is above this.
ALIGNS_ABOVE = 0.5


def tidy(x: float) -> float:
    """A coordinate with 10 significant digits (no 0.30000000000000004 in run names)."""
    return float(f"{x:.10g}")


@dataclass(frozen=True)
class Segment:
    """A straight path in key space, ``at(0) = start`` to ``at(1) = end``."""

    start: Coords
    end: Coords

    def at(self, t: float) -> Coords:
        return tuple(tidy(s + t * (e - s)) for s, e in zip(self.start, self.end, strict=True))

    def t_resolution(self, resolution: Sequence[float]) -> float:
        """The step in t that moves no key by more than its resolution."""
        steps = [r / abs(e - s) for s, e, r in zip(self.start, self.end, resolution, strict=True)
                 if e != s]
        return min(steps) if steps else 1.0


@dataclass
class Transition:
    """A change of verdict along a segment, bracketed to the resolution."""

    segment: int
    lo_t: float
    hi_t: float
    lo: Coords
    hi: Coords
    lo_fraction: float
    hi_fraction: float

    @property
    def rising(self) -> bool:
        """Aligns past the bracket (going along the segment), not before it: a lower limit."""
        return self.hi_fraction > ALIGNS_ABOVE

    @property
    def mid(self) -> Coords:
        return tuple(tidy((a + b) / 2) for a, b in zip(self.lo, self.hi, strict=True))


@dataclass
class SearchResult:
    segments: list[Segment]
    transitions: list[Transition]
    evaluated: dict[Coords, float] = field(default_factory=dict)
    rounds: int = 0


def search(
    evaluate: Evaluate, segments: Sequence[Segment], *, coarse: int,
    resolution: Sequence[float], max_rounds: int = 60,
) -> SearchResult:
    """Coarse grid along every segment, then bisection of every bracket where the
    verdict changes until each is within ``resolution`` (per key). Each round is one
    call of ``evaluate`` with all points of that round (parallel)."""
    if coarse < 2:
        raise ValueError("coarse grid needs at least 2 points")
    result = SearchResult(list(segments), [])
    cache = result.evaluated

    def batch(points: list[Coords]) -> None:
        new = list(dict.fromkeys(p for p in points if p not in cache))
        if new:
            for p, f in zip(new, evaluate(new), strict=True):
                cache[p] = float(f)
        result.rounds += 1

    ts = [tidy(i / (coarse - 1)) for i in range(coarse)]
    batch([seg.at(t) for seg in segments for t in ts])
    brackets: list[list[Any]] = []  # [segment, lo_t, hi_t]
    for i, seg in enumerate(segments):
        verdicts = [cache[seg.at(t)] > ALIGNS_ABOVE for t in ts]
        for a, b, va, vb in zip(ts, ts[1:], verdicts, verdicts[1:], strict=False):
            if va != vb:
                brackets.append([i, a, b])
    t_res = [seg.t_resolution(resolution) for seg in segments]
    for _ in range(max_rounds):
        active = [br for br in brackets if br[2] - br[1] > t_res[br[0]] * (1 + 1e-9)]
        if not active:
            break
        mids = [tidy((br[1] + br[2]) / 2) for br in active]
        batch([segments[br[0]].at(m) for br, m in zip(active, mids, strict=True)])
        for br, m in zip(active, mids, strict=True):
            seg = segments[br[0]]
            v_lo = cache[seg.at(br[1])] > ALIGNS_ABOVE
            if (cache[seg.at(m)] > ALIGNS_ABOVE) == v_lo:
                br[1] = m
            else:
                br[2] = m
    for i, lo_t, hi_t in brackets:
        seg = segments[i]
        lo, hi = seg.at(lo_t), seg.at(hi_t)
        result.transitions.append(Transition(i, lo_t, hi_t, lo, hi, cache[lo], cache[hi]))
    return result


def line(lo: float, hi: float) -> list[Segment]:
    """One key: the one segment from LO to HI."""
    return [Segment((tidy(lo),), (tidy(hi),))]


def rays(box: Sequence[tuple[float, float]], n: int) -> list[Segment]:
    """Two keys: ``n`` rays from the centre of the box to its edge, evenly spread in
    angle over the box normalised to a square."""
    (x0, x1), (y0, y1) = box
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    hx, hy = (x1 - x0) / 2, (y1 - y0) / 2
    out = []
    for k in range(n):
        a = 2 * math.pi * k / n
        c, s = math.cos(a), math.sin(a)
        scale = 1.0 / max(abs(c), abs(s))
        out.append(Segment((tidy(cx), tidy(cy)),
                           (tidy(cx + hx * c * scale), tidy(cy + hy * s * scale))))
    return out


def describe(result: SearchResult, keys: Sequence[str]) -> list[dict[str, Any]]:
    """The limits found, as rows: kind (lower: aligns above it; upper: aligns below it),
    the bracket and its middle, the aligned fraction at both ends."""
    rows = []
    for tr in result.transitions:
        kind = ("lower" if tr.rising else "upper") if len(keys) == 1 else "boundary"
        row: dict[str, Any] = {
            "ray": tr.segment, "kind": kind,
            "lo_fraction": tr.lo_fraction, "hi_fraction": tr.hi_fraction,
        }
        for j, key in enumerate(keys):
            row[key] = tr.mid[j]
            row[f"{key} from"] = tr.lo[j]
            row[f"{key} to"] = tr.hi[j]
        rows.append(row)
    return rows
