"""Plot of a friction estimate: position and velocity with the fit and its band."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ffexp import figures
from ffexp.errors import InputError
from ffexp.friction.estimate import FrictionResult
from ffexp.numfmt import fixed, pm

if TYPE_CHECKING:
    from matplotlib.figure import Figure


def plot_result(result: FrictionResult, out: Path) -> list[Path]:
    """Write a three-panel figure (position, velocity, residuals) as PNG and SVG.

    ``out`` names the figure (``a.png`` writes ``a.png`` and ``a.svg``); a
    taken name gets ``-1``, ``-2``, ... (:func:`ffexp.figures.save`). Returns
    the paths written.

    Position and velocity are along the motion direction; the fitted window is
    shaded; bands are ``± t_q`` standard errors of the fitted curve (the
    confidence level of the estimate). Velocity points are central
    differences of the tracked positions.

    Raises:
        InputError: the figure cannot be written to ``out``.
    """
    if out.suffix.lower() not in ("", ".png", ".svg"):
        raise InputError(f"{out}: a figure is written as .png and .svg, not {out.suffix}")
    with figures.style():
        fig = figures.new_figure(8, 8.5)
        axes = fig.subplots(3, 1, sharex=True, gridspec_kw={"height_ratios": [3, 3, 2]})
        _draw(result, fig, axes)
        return figures.save(fig, out.parent, out.stem)


def _draw(result: FrictionResult, fig: Figure, axes: Any) -> None:
    e = result.estimate
    f = e.fit
    t = result.track.t_s
    s = result.s_m
    ok = np.isfinite(s)
    win = result.window_idx
    tq = e.t_quantile
    t_fine = np.linspace(f.t_start_s, f.t_end_s, 300)
    x_fit = f.position_m(t_fine)
    x_band = tq * f.position_std_m(t_fine)
    v_fit = f.velocity_mps(t_fine)
    v_band = tq * f.velocity_std_m(t_fine)
    ax_x, ax_v, ax_r = axes
    for ax in axes:
        ax.axvspan(f.t_start_s, f.t_end_s, color="0.92", zorder=0, label="fit window")
    ax_x.plot(t[ok], s[ok] * 1e3, ".", ms=3, color="0.45", label="tracked")
    ax_x.plot(t[win], s[win] * 1e3, ".", ms=4, color="C0", label="fitted frames")
    ax_x.plot(t_fine, x_fit * 1e3, "-", color="C3", lw=1.2, label="fit")
    ax_x.fill_between(
        t_fine,
        (x_fit - x_band) * 1e3,
        (x_fit + x_band) * 1e3,
        color="C3",
        alpha=0.25,
        label=f"{round(100 * e.confidence)}% band",
    )
    ax_x.set_ylabel("position along motion [mm]")
    ax_x.legend(loc="lower right")
    idx = np.flatnonzero(ok)
    if idx.size >= 3:
        tc = t[idx]
        sc = s[idx]
        vc = np.gradient(sc, tc)
        ax_v.plot(tc, vc * 1e3, ".", ms=3, color="0.45", label="central difference")
    ax_v.plot(t_fine, v_fit * 1e3, "-", color="C3", lw=1.2, label="fit")
    ax_v.fill_between(
        t_fine, (v_fit - v_band) * 1e3, (v_fit + v_band) * 1e3, color="C3", alpha=0.25
    )
    ax_v.set_ylabel("velocity [mm/s]")
    ax_v.legend(loc="upper right")
    ax_r.fill_between(t_fine, -x_band * 1e6, x_band * 1e6, color="C3", alpha=0.25, label="fit band")
    ax_r.plot(t[win], f.residuals_m * 1e6, ".-", ms=3, lw=0.6, color="C0")
    ax_r.axhline(0.0, color="0.3", lw=0.8)
    ax_r.set_ylabel("residual [µm]")
    ax_r.set_xlabel("time [s]")
    sd = e.mu_std
    if e.significant:
        title = f"mu = {pm(e.mu, sd)}  [{fixed(e.mu_low, sd)}, {fixed(e.mu_high, sd)}]"
    else:
        title = f"mu < {fixed(e.mu_upper_bound, sd)}  (not significant: mu = {pm(e.mu, sd)})"
    fig.suptitle(
        f"{Path(result.video).name}: {title}\n"
        f"a = {pm(f.decel_mps2, f.decel_std_mps2)} m/s², "
        f"{f.n_frames} frames, {f.window_s:.2f} s"
    )
