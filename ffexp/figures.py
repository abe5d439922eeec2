"""The figures of ffexp, in one style: run figures, the campaign figure, saving.

One style for every figure (:data:`STYLE`: font sizes, line widths, grid,
one resolution :data:`DPI`), every figure written as PNG and SVG by
:func:`save`, which never overwrites: an existing name gets ``-1``, ``-2``...
Every axis carries one unit (forces in N and torques in N m sit on separate
axes), phase shading always comes with its legend, and the force figures
have a second panel at the scale of the contact force the experiment is
about (about 1 N), so that impact spikes do not squash it.

matplotlib is imported inside the functions (``ffexp --help`` stays fast).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from ffexp.contracts import Phase
from ffexp.errors import InputError
from ffexp.naming import unique_stem

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from ffexp.analysis import RunSeries
    from ffexp.recording import Recording

#: One resolution for every raster figure (dots per inch).
DPI = 150
#: Every figure is written in these formats.
FORMATS = ("png", "svg")
STYLE: dict[str, Any] = {
    "font.size": 9,
    "axes.titlesize": 9,
    "axes.labelsize": 9,
    "legend.fontsize": 7,
    "xtick.labelsize": 8,
    "ytick.labelsize": 8,
    "lines.linewidth": 0.9,
    "axes.grid": True,
    "grid.linestyle": ":",
    "grid.color": "0.6",
    "savefig.dpi": DPI,
    "svg.fonttype": "none",
}
PHASE_COLOURS = {
    Phase.APPROACH: "#dbe9f6", Phase.ALIGN: "#e3f1dc", Phase.DONE: "#eeeeee", Phase.ABORT: "#f8d7d3"
}
#: The zoomed force panel shows at least +-this much around f_ref (N).
ZOOM_MIN_N = 1.0


@contextmanager
def style() -> Iterator[None]:
    """Figures created inside the block get :data:`STYLE`."""
    import matplotlib as mpl

    with mpl.rc_context(cast(Any, STYLE)):
        yield


def new_figure(width_in: float, height_in: float) -> Figure:
    """A figure (call inside :func:`style`)."""
    from matplotlib.figure import Figure

    return Figure(figsize=(width_in, height_in), layout="constrained")


def save(fig: Figure, out_dir: Path, stem: str) -> list[Path]:
    """Write ``fig`` as ``out_dir/<stem>.png`` and ``.svg``; never overwrite.

    If either file exists, the stem gets ``-1``, ``-2``, ... (the first free
    one for both formats).

    Raises:
        InputError: ``out_dir`` is not a directory or cannot be written.
    """
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError(f"{out_dir}: exists and is not a directory (a figure directory)")
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        free = unique_stem(out_dir, stem, tuple(f".{f}" for f in FORMATS))
        paths = [out_dir / f"{free}.{fmt}" for fmt in FORMATS]
        for path in paths:
            fig.savefig(path, dpi=DPI)
            # the layout is done: the next format reuses it (half the time, same layout)
            fig.set_layout_engine("none")
    except OSError as exc:
        raise InputError(f"{exc.filename or out_dir}: cannot write: {exc.strerror}") from None
    return paths


# -- phases -------------------------------------------------------------------
def shade_phases(ax: Axes, s: RunSeries) -> None:
    """Shade each phase segment of the run (behind the lines)."""
    starts = np.flatnonzero(np.concatenate([[True], s.phase[1:] != s.phase[:-1]]))
    ends = np.concatenate([starts[1:], [len(s.phase) - 1]])
    for a, b in zip(starts, ends, strict=True):
        colour = PHASE_COLOURS.get(Phase(int(s.phase[a])))
        if colour:
            ax.axvspan(s.t_s[a], s.t_s[b], color=colour, lw=0, zorder=0)


def phase_legend(fig: Figure, s_list: Sequence[RunSeries]) -> None:
    """One legend for the phase shading of the figure (the phases that occur)."""
    from matplotlib.patches import Patch

    seen = {int(p) for s in s_list for p in np.unique(s.phase)}
    handles = [
        Patch(color=c, label=f"{ph.name} phase")
        for ph, c in PHASE_COLOURS.items() if int(ph) in seen
    ]
    if handles:
        fig.legend(handles=handles, loc="outside lower center", ncols=len(handles),
                   frameon=False, title="shading")


def _ref(s: RunSeries) -> np.ndarray:
    """f_ref along Z in ALIGN (NaN elsewhere, and all NaN for a method without one)."""
    if not np.any(s.f_ref[:, 2]):
        return np.full(len(s.t_s), np.nan)
    out: np.ndarray = np.where(s.phase == Phase.ALIGN, s.f_ref[:, 2], np.nan)
    return out


def _zoom_limits(s: RunSeries) -> tuple[float, float]:
    """The y range of the force-scale panel: f_ref (or the ALIGN median) +- max(1 N, 2 f_ref)."""
    f_z = -s.wrench[:, 2]
    in_align = s.phase == Phase.ALIGN
    ref = float(np.nanmedian(s.f_ref[in_align, 2])) if in_align.any() else 0.0
    centre = ref if ref > 0 else (float(np.median(f_z[in_align])) if in_align.any() else 0.0)
    half = max(ZOOM_MIN_N, 2.0 * abs(centre))
    return centre - half, centre + half


# -- run figures --------------------------------------------------------------
def wrench_figure(rec: Recording, title: str) -> Figure:
    """Measured contact wrench (the paper's exp_all_wrench, one run): f_z at full
    scale and at the force scale, lateral forces, torque about X; one unit per axis."""
    from ffexp.analysis import series

    s = series(rec)
    fig = new_figure(7.5, 7.5)
    axes = fig.subplots(4, 1, sharex=True, height_ratios=[2, 2, 2, 2])
    f_z = -s.wrench[:, 2]
    for ax in axes:
        shade_phases(ax, s)
    ax = axes[0]
    ax.plot(s.t_s, f_z, label="f_z = -w_z (contact, pushing > 0)")
    ax.plot(s.t_s, _ref(s), "k--", label="f_z ref")
    ax.set_ylabel("f_z [N]\n(full scale)")
    ax.legend(loc="upper left")
    ax = axes[1]
    ax.plot(s.t_s, f_z)
    ax.plot(s.t_s, _ref(s), "k--")
    ax.set_ylim(*_zoom_limits(s))
    ax.set_ylabel("f_z [N]\n(force scale)")
    ax = axes[2]
    ax.plot(s.t_s, s.wrench[:, 1], color="tab:orange", label="w_y (lateral)")
    ax.plot(s.t_s, s.wrench[:, 0], color="tab:gray", lw=0.7, label="w_x (vertical)")
    ax.set_ylabel("force [N]")
    ax.legend(loc="upper left")
    ax = axes[3]
    ax.plot(s.t_s, s.wrench[:, 3], color="tab:green", label="t_x")
    ax.set_ylabel("torque X [N m]")
    ax.set_xlabel("time since start [s]")
    ax.legend(loc="upper left")
    phase_legend(fig, [s])
    fig.suptitle(f"{title}\nmeasured contact wrench (TCF, environment on tool)")
    return fig


def applied_figure(rec: Recording, title: str) -> Figure:
    """f_z; contact vs applied force along Y; contact vs applied torque about X
    (the paper's exp_fc_tri, exp_fc_ti_1 and exp_fc)."""
    from ffexp.analysis import series

    s = series(rec)
    fig = new_figure(12.0, 4.0)
    axes = fig.subplots(1, 3)
    panels = [
        ("(a) contact force along Z", -s.wrench[:, 2], s.applied[:, 2], "f_z [N]", "F*_z applied"),
        ("(b) force along Y", s.wrench[:, 1], s.applied[:, 1], "f_y [N]", "F*_y applied"),
        ("(c) torque about X", s.wrench[:, 3], s.applied[:, 3], "t_x [N m]", "T*_x applied"),
    ]
    for ax, (name, contact, applied, unit, applied_label) in zip(axes, panels, strict=True):
        shade_phases(ax, s)
        ax.plot(s.t_s, contact, label="contact (measured)")
        ax.plot(s.t_s, applied, label=applied_label)
        if name.startswith("(a)"):
            ax.plot(s.t_s, _ref(s), "k--", label="f_z ref")
            ax.set_ylim(*_zoom_limits(s))
            ax.set_title(name + " (force scale; spikes clipped)")
        else:
            ax.set_title(name)
        ax.set_xlabel("time since start [s]")
        ax.set_ylabel(unit)
        ax.legend(loc="upper left")
    phase_legend(fig, [s])
    fig.suptitle(f"{title}\ncontact and applied wrench")
    return fig


def campaign_figure(recs: Sequence[tuple[str, Recording]], title: str) -> Figure:
    """f_z at the force scale per run, lateral force and torque on their own axes."""
    from ffexp.analysis import series

    n = len(recs)
    fig = new_figure(11.0, 1.9 * n + 1.2)
    axes = np.atleast_2d(fig.subplots(n, 2, sharex=True, squeeze=False))
    seen = []
    twins = []
    for row, (name, rec) in zip(axes, recs, strict=True):
        s = series(rec)
        seen.append(s)
        ax_f, ax_l = row
        shade_phases(ax_f, s)
        shade_phases(ax_l, s)
        ax_f.plot(s.t_s, -s.wrench[:, 2], label="f_z")
        ax_f.plot(s.t_s, _ref(s), "k--", label="f_z ref")
        ax_f.set_ylim(*_zoom_limits(s))
        ax_f.set_ylabel("f_z [N]")
        ax_f.set_title(name, loc="left")
        ax_l.plot(s.t_s, s.wrench[:, 1], color="tab:orange", label="w_y [N]")
        ax_l.set_ylabel("w_y [N]")
        ax_t = ax_l.twinx()
        ax_t.plot(s.t_s, s.wrench[:, 3], color="tab:green", label="t_x [N m]")
        ax_t.set_ylabel("t_x [N m]", color="tab:green")
        ax_t.grid(False)
        twins.append(ax_t)
        ax_l.set_title("lateral force (left axis), torque about X (right axis)", loc="left")
    for ax in axes[-1]:
        ax.set_xlabel("time since start [s]")
    axes[0][0].legend(loc="upper left")
    lines = [*axes[0][1].get_lines(), *twins[0].get_lines()]
    axes[0][1].legend(lines, [str(h.get_label()) for h in lines], loc="upper left")
    phase_legend(fig, seen)
    fig.suptitle(f"{title}: contact force at the force scale; lateral wrench (TCF)")
    return fig


def write_run_figures(rec: Recording, out_dir: Path, name: str) -> list[Path]:
    """The per-run figures (PNG and SVG) as ``<name>_wrench`` and ``<name>_applied``."""
    paths: list[Path] = []
    with style():
        for suffix, make in (("wrench", wrench_figure), ("applied", applied_figure)):
            paths.extend(save(make(rec, name), out_dir, f"{name}_{suffix}"))
    return paths
