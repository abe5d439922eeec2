"""The paper's claims as small pure functions of result rows (``ffexp reproduce``).

A scene's runs are a mapping role -> row (a row of the results table: at least
``outcome``, ``breaks_align``, ``mean_fz_align_n``, ``f_ref_n``, ``error``). A run
is named by :func:`ffexp.outcome.classify` (``outcome``); a run that was stopped,
aborted or is incomplete cannot judge a claim (rows of older tables without an
outcome: ``aligned`` and ``contact_breaks``).
Roles: ``I-1`` (Method I case I at 0.8 N), ``I-2`` (case II at 0.8 N),
``II-0.8`` and ``II-1.5`` (Method II at 0.8 and 1.5 N), ``III`` (impedance).
A claim returns True or False, or None when it cannot be judged (a run it
needs is missing or failed). Limit claims take the limits found at the
nominal scene (rows of :func:`ffexp.sweeps.limits.describe`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from ffexp import outcome as oc

Row = Mapping[str, Any]
Runs = Mapping[str, Row]
ROLES = ("I-1", "I-2", "II-0.8", "II-1.5", "III")


@dataclass(frozen=True)
class Settings:
    """Thresholds of the claims (``[claims]`` of protocols/reproduce.toml)."""

    iii_min_breaks: int = 3
    """Rows without an ``outcome`` only: Method III "breaks contact" with at least this many
    breaks after the first contact."""
    fz_tolerance: float = 0.15
    """f_z tracking: |mean f_z in ALIGN - f_ref| <= this fraction of f_ref."""
    limit_factor: float = 2.0
    """A limit agrees with the paper's when within this factor of it."""
    i1_max_breaks: int = 1
    """Method I case I aligns "with at most this many contact breaks in ALIGN"."""


def _usable(runs: Runs, *roles: str) -> bool:
    return all(role in runs and not runs[role].get("error")
               and runs[role].get("outcome") not in oc.NOT_SCORED for role in roles)


def _aligned(row: Row) -> bool:
    if row.get("outcome"):
        return bool(row["outcome"] == oc.ALIGNED)
    return bool(row.get("aligned"))


def _kept_breaking(row: Row, s: Settings) -> bool:
    if row.get("outcome"):
        return oc.kept_breaking(str(row["outcome"]), int(row.get("breaks_after_transient") or 0))
    return _breaks(row) >= s.iii_min_breaks


def _did_not_slide(row: Row) -> bool:
    if row.get("outcome"):
        return bool(row["outcome"] == oc.HELD)
    return not _aligned(row)


def _breaks(row: Row) -> int:
    """Contact breaks after the first contact, the whole run."""
    return int(row.get("contact_breaks") or 0)


def _breaks_align(row: Row) -> int:
    """Contact breaks within ALIGN before the seat (older rows: all breaks)."""
    value = row.get("breaks_align")
    return _breaks(row) if value is None else int(value)


def i1_aligns(runs: Runs, s: Settings) -> bool | None:
    """Method I case I aligns at 0.8 N with at most ``i1_max_breaks`` breaks in ALIGN."""
    if not _usable(runs, "I-1"):
        return None
    return _aligned(runs["I-1"]) and _breaks_align(runs["I-1"]) <= s.i1_max_breaks


def ii_low_fails(runs: Runs, s: Settings) -> bool | None:
    """Method II at 0.8 N holds contact without sliding (the paper: no sliding below 1 N)."""
    if not _usable(runs, "II-0.8"):
        return None
    return _did_not_slide(runs["II-0.8"])


def ii_high_aligns(runs: Runs, s: Settings) -> bool | None:
    """Method II at 1.5 N aligns."""
    if not _usable(runs, "II-1.5"):
        return None
    return _aligned(runs["II-1.5"])


def iii_breaks(runs: Runs, s: Settings) -> bool | None:
    """Method III's contact kept breaking (at least two breaks after the first contact's
    transient, :func:`ffexp.outcome.kept_breaking`, a seat at the end or not)."""
    if not _usable(runs, "III"):
        return None
    return _kept_breaking(runs["III"], s)


def ordering(runs: Runs, s: Settings) -> bool | None:
    """The paper's comparison: I-1 aligns at 0.8 N (at most ``i1_max_breaks`` breaks in
    ALIGN); II does not at 0.8 N but does at 1.5 N; III's contact keeps breaking."""
    verdicts = [f(runs, s) for f in (i1_aligns, ii_low_fails, ii_high_aligns, iii_breaks)]
    if any(v is None for v in verdicts):
        return None
    return all(verdicts)


def i2_aligns(runs: Runs, s: Settings) -> bool | None:
    """Method I case II (k_yp only) aligns at 0.8 N."""
    if not _usable(runs, "I-2"):
        return None
    return _aligned(runs["I-2"])


def fz_tracking(runs: Runs, s: Settings, roles: Sequence[str] = ("I-1", "I-2", "II-1.5")
                ) -> bool | None:
    """Mean f_z in ALIGN within ``fz_tolerance`` of f_ref for the runs of I and II that
    reached ALIGN (None when none of them did)."""
    judged = []
    for role in roles:
        if not _usable(runs, role):
            continue
        fz, ref = runs[role].get("mean_fz_align_n"), runs[role].get("f_ref_n")
        if fz is None or ref is None or not ref:
            continue
        judged.append(abs(float(fz) - float(ref)) <= s.fz_tolerance * abs(float(ref)))
    return all(judged) if judged else None


def all_claims(runs: Runs, s: Settings) -> bool | None:
    """Every scene claim above at once (case II included)."""
    verdicts = [ordering(runs, s), i2_aligns(runs, s), fz_tracking(runs, s)]
    if any(v is None for v in verdicts):
        return None
    return all(verdicts)


@dataclass(frozen=True)
class SceneClaim:
    name: str
    paper: str
    judge: Callable[[Runs, Settings], bool | None]


SCENE_CLAIMS: tuple[SceneClaim, ...] = (
    SceneClaim("I-1 aligns", "Method I case I aligns at f_ref 0.8 N (at most one contact "
               "break in ALIGN)", i1_aligns),
    SceneClaim("II at 0.8 N fails", "without inertia reduction the tool does not slide "
               "below 1 N (held contact, did not slide)", ii_low_fails),
    SceneClaim("II at 1.5 N aligns", "Method II aligns at f_ref 1.5 N", ii_high_aligns),
    SceneClaim("III breaks contact", "impedance control: the contact kept breaking "
               "(breaks recur after the first contact's transient)", iii_breaks),
    SceneClaim("ordering", "all four above: direct force control aligns, impedance "
               "control keeps losing contact", ordering),
    SceneClaim("I-2 aligns at 0.8 N", "Method I case II (k_yp 1) aligns at f_ref 0.8 N",
               i2_aligns),
    SceneClaim("f_z tracking", "mean f_z in ALIGN tracks f_ref (within 15 %) for I and II",
               fz_tracking),
    SceneClaim("all", "every claim above", all_claims),
)


# -- limits at the nominal scene -------------------------------------------------------
def lower_upper(found: Sequence[Row], key: str) -> tuple[float | None, float | None, int]:
    """The lowest lower limit and the highest upper limit of ``key`` (None when there is
    none) and how many limits there are."""
    lows = [float(r[key]) for r in found if r.get("kind") == "lower"]
    highs = [float(r[key]) for r in found if r.get("kind") == "upper"]
    return (min(lows) if lows else None, max(highs) if highs else None, len(found))


def gain_limits(found: Sequence[Row], key: str, paper: tuple[float, float], s: Settings
                ) -> bool:
    """One lower and one upper limit, lower below upper, each within ``limit_factor``
    of the paper's."""
    lo, hi, n = lower_upper(found, key)
    if lo is None or hi is None or n != 2 or not lo < hi:
        return False
    return _near(lo, paper[0], s.limit_factor) and _near(hi, paper[1], s.limit_factor)


def _near(x: float, ref: float, factor: float) -> bool:
    if ref == 0:
        return x == 0
    return ref / factor <= x <= ref * factor


def minimum_aligning(found: Sequence[Row], key: str, aligns_at_low_end: bool, low_end: float
                     ) -> float | None:
    """The smallest value that aligns: the range's low end when it aligns there, else
    the lowest lower limit; None when nothing in the range aligns."""
    if aligns_at_low_end:
        return low_end
    return lower_upper(found, key)[0]


def minimum_f_ref(min_with_ri: float | None, min_without: float | None,
                  at_n: float = 0.8, high_n: float = 1.5) -> bool:
    """With inertia reduction the run aligns at ``at_n``; without it needs more than
    ``at_n`` and at most ``high_n`` (the paper: 0.8 N and 1.5 N)."""
    return (min_with_ri is not None and min_with_ri <= at_n
            and min_without is not None and at_n < min_without <= high_n)


def summarize(per_scene: Sequence[Mapping[str, bool | None]], claims: Sequence[SceneClaim]
              ) -> list[dict[str, Any]]:
    """Claim by claim: in how many scenes it holds, of how many it could be judged in."""
    out = []
    for c in claims:
        verdicts = [v[c.name] for v in per_scene]
        judged = [v for v in verdicts if v is not None]
        holds = sum(1 for v in judged if v)
        out.append({"claim": c.name, "paper": c.paper, "holds": holds, "scenes": len(judged),
                    "fraction": holds / len(judged) if judged else None,
                    "not judged": len(verdicts) - len(judged)})
    return out


def neighbour_flips(
    scenes: Sequence[Mapping[str, Any]], verdicts: Sequence[bool | None],
    axes: Sequence[tuple[str, Sequence[Any]]],
) -> tuple[int, int]:
    """How often an outcome differs between neighbouring points of a grid, and of how
    many neighbouring pairs (both judged). Neighbours differ by one step along one axis;
    ``verdicts[i]`` is scene i's outcome (None: not judged); scenes off the grid (the
    nominal one) are ignored. A smooth outcome flips only along its boundary."""
    index: dict[tuple[int, ...], bool | None] = {}
    for scene, verdict in zip(scenes, verdicts, strict=True):
        try:
            at = tuple(list(values).index(scene[name]) for name, values in axes)
        except (KeyError, ValueError):
            continue
        index[at] = verdict
    flips = pairs = 0
    for at, verdict in index.items():
        for axis in range(len(axes)):
            nxt = (*at[:axis], at[axis] + 1, *at[axis + 1:])
            other = index.get(nxt)
            if verdict is None or other is None:
                continue
            pairs += 1
            flips += verdict != other
    return flips, pairs


# -- where a claim holds ----------------------------------------------------------------
def region(per_scene: Sequence[Mapping[str, Any]], claim: str,
           keys: Sequence[str], nominal: Mapping[str, float]) -> dict[str, Any]:
    """Where ``claim`` holds over the scenes: the fraction of the judged scenes, and the
    centre of those where it holds (each key's mean over them; the nominal scene's keys
    are its ``nominal`` values) beside the nominal values and, per key, the span of
    the scenes where it holds as a fraction of the box's (0: one scene, 1: the whole
    range). An empty region has no centre."""
    judged = [e for e in per_scene if e.get(claim) is not None]
    inside = [e for e in judged if e[claim]]
    out: dict[str, Any] = {"claim": claim, "holds": len(inside), "scenes": len(judged),
                           "fraction": len(inside) / len(judged) if judged else None,
                           "centre": {}, "nominal": dict(nominal), "span": {}}
    for key in keys:
        def value(e: Mapping[str, Any], key: str = key) -> float | None:
            v = e.get(key)
            return float(v) if isinstance(v, int | float) else nominal.get(key)
        everywhere = [v for v in (value(e) for e in per_scene) if v is not None]
        here = [v for v in (value(e) for e in inside) if v is not None]
        if not here or not everywhere:
            continue
        out["centre"][key] = sum(here) / len(here)
        width = max(everywhere) - min(everywhere)
        out["span"][key] = (max(here) - min(here)) / width if width > 0 else 0.0
    return out
