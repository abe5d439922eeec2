"""Field-by-field difference of two recordings (``ffexp diff``), with a tolerance.

Compares the numeric (CDR) topics the two recordings have in common, or the ones
asked for, column by column as :mod:`ffexp.recording.frames` splits them (array
fields element by element: ``wrench_1``). Two values differ when
``|a - b| > max(atol, rtol * max(|a|, |b|))`` (openpilot's process-replay rule:
absolute near zero, relative on large values); two NaNs are equal, a NaN and a
number are not.

Alignment: each recording's times are taken from its own run start
(:attr:`~ffexp.recording.Recording.run_start_ns`, the first cycle), so a
replay (same log times) pairs cycle by cycle and two runs started at different
wall times still line up by run time. Each message of A inside the time span both
recordings cover on that topic is paired with B's newest message at or before
the same run time (a sample-and-hold of B: exact pairs when both have a message
at that time, as cycle topics of one rig do); A's messages outside B's span are
not compared, and the report says how many were paired of how many.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ffexp.errors import ConfigError, InputError
from ffexp.recording import Recording
from ffexp.recording.frames import flat_columns, seconds


def within(a: np.ndarray, b: np.ndarray, rtol: float, atol: float) -> np.ndarray:
    """Element-wise: ``a`` and ``b`` agree within the combined tolerance (NaN == NaN)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        d = np.abs(a - b)
        tol = np.maximum(atol, rtol * np.maximum(np.abs(a), np.abs(b)))
        ok = d <= tol
    both_nan = np.isnan(a) & np.isnan(b)
    same_inf = np.isinf(a) & (a == b)
    out: np.ndarray = ok | both_nan | same_inf
    return out


@dataclass(frozen=True)
class FieldDiff:
    """One column of one topic that differs beyond the tolerance."""

    topic: str
    column: str
    max_abs: float
    """Largest |a - b| over the paired messages (NaN against a number: inf)."""
    at_s: float
    """Run time of the largest difference [s]."""
    first_s: float
    """Run time where the difference first exceeds the tolerance [s]."""
    count: int
    """Paired messages beyond the tolerance."""


@dataclass
class TopicDiff:
    """One topic: how it was paired and the columns that differ."""

    topic: str
    n_a: int
    n_b: int
    paired: int
    span_s: tuple[float, float] | None
    fields: list[FieldDiff] = field(default_factory=list)
    max_abs: float = 0.0
    """Largest |a - b| of any column (also when within tolerance)."""
    note: str = ""
    """Why it could not be compared (absent in one file, no common span, other fields)."""

    @property
    def ok(self) -> bool:
        return not self.fields and not self.note


@dataclass
class DiffResult:
    """What :func:`diff` found."""

    a: Path
    b: Path
    rtol: float
    atol: float
    topics: list[TopicDiff]
    only_a: list[str]
    """Topics only A has (not compared unless asked for)."""
    only_b: list[str]

    @property
    def ok(self) -> bool:
        return all(t.ok for t in self.topics)

    @property
    def first(self) -> FieldDiff | None:
        """The earliest difference of all."""
        all_fields = [f for t in self.topics for f in t.fields]
        return min(all_fields, key=lambda f: f.first_s, default=None)


def check_tolerance(option: str, value: float) -> None:
    if not (np.isfinite(value) and value >= 0.0):
        raise ConfigError(option, str(value), "must be finite and >= 0")


def _pair(ta: np.ndarray, tb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Indices of A's messages inside B's span and of B's newest message at or before
    each (both times relative to their run start, integer ns)."""
    if not len(ta) or not len(tb):
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    ia = np.nonzero((ta >= tb[0]) & (ta <= max(tb[-1], tb[0])))[0]
    ib = np.searchsorted(tb, ta[ia], side="right") - 1
    return ia, ib


def diff_topic(a: Recording, b: Recording, topic: str, rtol: float, atol: float) -> TopicDiff:
    """Compare one CDR topic of ``a`` and ``b`` (see the module's description)."""
    da, db = a.topics.get(topic), b.topics.get(topic)
    if da is None or db is None:
        missing = a.path if da is None else b.path
        n_a, n_b = (len(da) if da is not None else 0), (len(db) if db is not None else 0)
        return TopicDiff(topic, n_a, n_b, 0, None, note=f"absent in {missing}")
    out = TopicDiff(topic, len(da), len(db), 0, None)
    ta = da.log_time_ns - np.int64(a.run_start_ns)
    tb = db.log_time_ns - np.int64(b.run_start_ns)
    ia, ib = _pair(ta, tb)
    out.paired = len(ia)
    if not len(ia):
        out.note = "no messages at common run times"
        return out
    t_s = seconds(ta[ia], 0)
    out.span_s = (float(t_s[0]), float(t_s[-1]))
    ca, cb = flat_columns(da), flat_columns(db)
    if set(ca) != set(cb):
        only = sorted(set(ca) ^ set(cb))
        out.note = f"the fields differ ({', '.join(only[:4])}{' ...' if len(only) > 4 else ''})"
    for name in ca:
        if name not in cb:
            continue
        va = ca[name][ia].astype(np.float64)
        vb = cb[name][ib].astype(np.float64)
        ok = within(va, vb, rtol, atol)
        with np.errstate(invalid="ignore"):
            d = np.where(np.isnan(va) & np.isnan(vb), 0.0, np.abs(va - vb))
        d = np.where(np.isnan(d), np.inf, d)
        k = int(np.argmax(d))
        out.max_abs = max(out.max_abs, float(d[k]))
        if ok.all():
            continue
        first = int(np.argmin(ok))
        out.fields.append(FieldDiff(topic, name, float(d[k]), float(t_s[k]), float(t_s[first]),
                                    int((~ok).sum())))
    return out


def diff(a: Recording, b: Recording, topics: Sequence[str] = (), *, rtol: float = 1e-9,
         atol: float = 1e-9) -> DiffResult:
    """Compare the CDR topics of two loaded recordings: ``topics``, or every topic both
    have. A topic asked for that neither has is bad input (:class:`InputError`); one
    that only one has is a difference."""
    check_tolerance("--rtol", rtol)
    check_tolerance("--atol", atol)
    for t in topics:
        if t not in a.topics and t not in b.topics:
            if t in a.json or t in b.json:
                raise InputError(f"{a.path}: {t} is a JSON topic; diff compares numeric (CDR) "
                                 "topics")
            raise InputError(f"{a.path}, {b.path}: no topic {t} in either recording")
    names = list(topics) if topics else [t for t in a.topics if t in b.topics]
    result = DiffResult(a.path, b.path, rtol, atol, [],
                        sorted(set(a.topics) - set(b.topics)),
                        sorted(set(b.topics) - set(a.topics)))
    for t in names:
        result.topics.append(diff_topic(a, b, t, rtol, atol))
    return result


def column_unit(topic: str, column: str) -> str:
    """The unit of a column of a registered topic (``wrench_4`` of a ``N, N m`` field:
    ``N m``), or ``""``."""
    from ffexp.recording.topics import CDR_TOPICS

    t = CDR_TOPICS.get(topic)
    if t is None:
        return ""
    for f in t.spec.fields:
        if column == f.name:
            return f.unit
        prefix, _, index = column.rpartition("_")
        if prefix == f.name and index.isdigit():
            units = [u.strip() for u in f.unit.split(",")]
            if len(units) == 2 and f.count == 6:  # [force, torque] halves
                return units[int(index) // 3]
            return f.unit
    return ""


def figure(result: DiffResult, a: Recording, b: Recording, out_dir: Path, stem: str,
           max_panels: int = 12) -> list[Path]:
    """One panel per differing column (the first ``max_panels``, earliest first): A and B
    over run time, the first excess marked; PNG and SVG in the house style."""
    from ffexp import figures

    diffs = sorted((f for t in result.topics for f in t.fields), key=lambda f: f.first_s)
    diffs = diffs[:max_panels]
    if not diffs:
        return []
    with figures.style():
        fig = figures.new_figure(7.0, 1.6 * len(diffs) + 0.6)
        axes = fig.subplots(len(diffs), 1, sharex=True, squeeze=False)[:, 0]
        for ax, f in zip(axes, diffs, strict=True):
            for rec, label, style in ((a, "A", "-"), (b, "B", "--")):
                data = rec.topics[f.topic]
                col = flat_columns(data)[f.column]
                ax.plot(seconds(data.log_time_ns, rec.run_start_ns), col, style,
                        label=f"{label}: {rec.path.name}")
            ax.axvline(f.first_s, color="0.3", linewidth=0.7, linestyle=":")
            unit = column_unit(f.topic, f.column)
            ax.set_ylabel(f"{f.column} [{unit}]" if unit else f.column)
            ax.set_title(f"{f.topic} {f.column}: max |A-B| {f.max_abs:.3g} at {f.at_s:.3f} s; "
                         f"beyond tol. from {f.first_s:.3f} s (dotted)", loc="left")
        axes[0].legend(loc="upper left")
        axes[-1].set_xlabel("run time [s]")
        fig.suptitle(f"diff: rtol {result.rtol:g}, atol {result.atol:g}")
        return figures.save(fig, out_dir, stem)
