"""Recorded against simulated measurements: residuals, the sensor's bias and delay, outcomes.

Pure: arrays in, arrays out. Each signal's residual is divided by its scale
(:data:`SCALES`, about what one would call a clear mismatch) and by the
square root of its number of values, so every signal of every recording
weighs the same in the cost whatever its rate and length.

The F/T sensor: the simulated reading is ideal (no bias, noise or delay); a
recording's bias is the mean difference over its quiet start (the cycles
before the robot commanded, arm held, no contact), and the path's delay is a
whole-sample shift of the simulated series.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ffexp.calibrate.inputs import ReplayInput
from ffexp.calibrate.resim import Trace

#: Signals compared, in this order.
SIGNALS = ("tcp", "joints", "force", "torque", "target", "yaw")
#: Scale of each signal's residual [m, rad, N, N m, m, rad].
SCALES = {"tcp": 1e-4, "joints": 1e-4, "force": 0.1, "torque": 5e-3, "target": 1e-3,
          "yaw": 1e-2}
UNITS = {"tcp": "m", "joints": "rad", "force": "N", "torque": "N m", "target": "m",
         "yaw": "rad"}
#: A residual where the simulation stopped early (scaled units).
FAILED = 100.0
#: Contact: force change from the quiet start above this [N], averaged over a cycle.
CONTACT_N = 1.0
#: Quiet start used when the robot commanded from its first cycle [s].
QUIET_S = 0.2


@dataclass
class Comparison:
    """One recording against one simulated replay."""

    residual: np.ndarray
    """Scaled residuals of every signal, concatenated."""
    rms: dict[str, float] = field(default_factory=dict)
    """RMS difference per signal in its unit (``nan``: not in the recording)."""
    bias: np.ndarray = field(default_factory=lambda: np.zeros(6))
    noise_floor_n: float = float("nan")
    """RMS of the recorded force about its mean over the quiet start [N]."""

    @property
    def cost(self) -> float:
        return float(self.residual @ self.residual)


def quiet_end_s(inp: ReplayInput) -> float:
    """End of the quiet start [s]: the last cycle before the robot commanded."""
    if inp.start_cycles >= 4:
        return float(inp.t_s[inp.start_cycles - 1])
    return QUIET_S


def ft_on_recorded(inp: ReplayInput, tr: Trace, shift: int) -> np.ndarray:
    """The simulated F/T at each recorded sample's time, ``shift`` samples late (nan: none)."""
    out = np.full_like(inp.ft, np.nan)
    if len(tr.ft_t_s) < 2:
        return out
    dt = float(np.median(np.diff(tr.ft_t_s)))
    idx = np.rint((inp.ft_t_s - tr.ft_t_s[0]) / dt).astype(np.int64) - shift
    ok = (idx >= 0) & (idx < len(tr.ft))
    out[ok] = tr.ft[idx[ok]]
    return out


def ft_period_s(tr: Trace) -> float:
    return float(np.median(np.diff(tr.ft_t_s))) if len(tr.ft_t_s) > 1 else 0.001


def _block(diff: np.ndarray, scale: float) -> np.ndarray:
    d = np.where(np.isfinite(diff), diff / scale, FAILED).ravel()
    return np.asarray(d / np.sqrt(max(d.size, 1)))


def _wrap(a: np.ndarray) -> np.ndarray:
    return np.asarray((a + np.pi) % (2 * np.pi) - np.pi)


def contact_onset_s(inp: ReplayInput) -> float:
    """Run time of the recording's first contact (its force off the quiet start), or inf."""
    mag = _contact_force(inp.ft_t_s, inp.ft[:, :3], quiet_end_s(inp), inp.cycle_s)
    on = np.flatnonzero(mag > CONTACT_N)
    return float(inp.ft_t_s[on[0]]) if on.size else math.inf


def compare(inp: ReplayInput, tr: Trace, shift: int,
            signals: Sequence[str] = SIGNALS, until_s: float = math.inf) -> Comparison:
    """Residuals of ``tr`` (a replay of ``inp``) against ``inp``'s measurements, on the
    recording's run time before ``until_s`` (the whole of it by default)."""
    blocks: list[np.ndarray] = []
    rms: dict[str, float] = {s: float("nan") for s in SIGNALS}
    n = min(inp.cycles, len(tr.t_s), int(np.searchsorted(inp.t_s, until_s)))
    diffs: dict[str, np.ndarray] = {
        "tcp": inp.tcp[:n] - tr.tcp[:n],
        "joints": inp.joints[:n] - tr.joints[:n, :inp.joints.shape[1]],
    }
    sim_ft = ft_on_recorded(inp, tr, shift)
    quiet = inp.ft_t_s <= quiet_end_s(inp)
    bias = np.nanmean(inp.ft[quiet] - sim_ft[quiet], axis=0) if quiet.any() else np.zeros(6)
    bias = np.where(np.isfinite(bias), bias, 0.0)
    ft_diff = inp.ft - sim_ft - bias
    # before the delayed series starts: nothing to compare
    ft_diff = ft_diff[max(shift, 0):int(np.searchsorted(inp.ft_t_s, until_s))]
    diffs["force"], diffs["torque"] = ft_diff[:, :3], ft_diff[:, 3:]
    floor = float(np.sqrt(np.mean((inp.ft[quiet, :3] - inp.ft[quiet, :3].mean(0)) ** 2))) \
        if quiet.sum() > 2 else float("nan")
    k = int(np.searchsorted(inp.target_t_s, until_s))
    if k and n:
        sim = np.column_stack([np.interp(inp.target_t_s[:k], tr.t_s[:n], tr.target[:n, i])
                               for i in range(3)])
        diffs["target"] = inp.target[:k, :2] - sim[:, :2]
        diffs["yaw"] = _wrap(inp.target[:k, 2] - sim[:, 2])
    for s in signals:
        d = diffs.get(s)
        if d is None or d.size == 0:
            continue
        blocks.append(_block(d, SCALES[s]))
        finite = d[np.isfinite(d)]
        rms[s] = float(np.sqrt(np.mean(finite ** 2))) if finite.size else float("inf")
    res = np.concatenate(blocks) if blocks else np.zeros(0)
    return Comparison(residual=res, rms=rms, bias=bias, noise_floor_n=floor)


def best_shift(inp: Sequence[ReplayInput], traces: Sequence[Trace], lo: int, hi: int,
               ) -> tuple[int, dict[int, float]]:
    """The F/T delay in whole samples in ``[lo, hi]`` that fits every recording best."""
    costs = {s: sum(compare(i, t, s, ("force", "torque")).cost for i, t in
                    zip(inp, traces, strict=True)) for s in range(lo, hi + 1)}
    return min(costs, key=lambda s: costs[s]), costs


@dataclass(frozen=True)
class Outcome:
    """A run's outcome as both sides can tell it: seated at the end, contact breaks."""

    aligned: bool | None
    breaks: int
    contact: bool

    def agrees(self, other: Outcome) -> bool:
        same = self.aligned is None or other.aligned is None or self.aligned == other.aligned
        return same and abs(self.breaks - other.breaks) <= 1 and self.contact == other.contact

    def text(self) -> str:
        a = {None: "alignment unknown", True: "aligned", False: "not aligned"}[self.aligned]
        return f"{a}, {self.breaks} break(s)" if self.contact else f"{a}, no contact"


def _contact_force(t_s: np.ndarray, force: np.ndarray, quiet_s: float,
                   cycle_s: float) -> np.ndarray:
    """The force's change from its quiet-start mean, averaged over a cycle [N]."""
    if len(t_s) < 3:
        return np.zeros(len(t_s))
    ref = force[t_s <= quiet_s].mean(axis=0) if (t_s <= quiet_s).any() else force[0]
    mag = np.linalg.norm(force - ref, axis=1)
    width = _width(t_s, cycle_s)
    return np.asarray(np.convolve(mag, np.ones(width) / width, mode="same"))


def _width(t_s: np.ndarray, cycle_s: float) -> int:
    return max(1, round(cycle_s / max(float(np.median(np.diff(t_s))), 1e-9)))


def contact_breaks(t_s: np.ndarray, force: np.ndarray, quiet_s: float,
                   cycle_s: float) -> tuple[bool, int]:
    """Contact from the force's change over the quiet start; breaks: contact lost after the
    first contact for at least two cycles."""
    if len(t_s) < 3:
        return False, 0
    width = _width(t_s, cycle_s)
    on = _contact_force(t_s, force, quiet_s, cycle_s) > CONTACT_N
    if not on.any():
        return False, 0
    per_cycle = max(1, width)
    breaks = 0
    i = int(np.argmax(on))
    while i < len(on):
        off = np.flatnonzero(~on[i:])
        if not off.size:
            break
        j = i + int(off[0])
        back = np.flatnonzero(on[j:])
        end = j + int(back[0]) if back.size else len(on)
        if end - j >= 2 * per_cycle:
            breaks += 1 if back.size else 0
        i = end
    return True, breaks


def outcomes(inp: ReplayInput, tr: Trace, shift: int) -> tuple[Outcome, Outcome]:
    """The recorded and the simulated outcome of one replay."""
    q = quiet_end_s(inp)
    rec_c, rec_b = contact_breaks(inp.ft_t_s, inp.ft[:, :3], q, inp.cycle_s)
    sim_ft = ft_on_recorded(inp, tr, shift)
    ok = np.isfinite(sim_ft).all(axis=1)
    sim_c, sim_b = contact_breaks(inp.ft_t_s[ok], sim_ft[ok, :3], q, inp.cycle_s)
    sim_seated = bool(tr.seated[-1]) if len(tr.seated) and inp.truth_seated is not None \
        else None
    return (Outcome(inp.truth_seated, rec_b, rec_c), Outcome(sim_seated, sim_b, sim_c))
