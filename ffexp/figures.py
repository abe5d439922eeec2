"""The figures of ffexp, in one style: run figures, the campaign figure, saving.

One style for every figure (:data:`STYLE`: font sizes, line widths, grid,
one resolution :data:`DPI`), every figure written as PNG and SVG by
:func:`save`, which never overwrites: an existing name gets ``-1``, ``-2``...
Every axis carries one unit (forces in N and torques in N m sit on separate
axes; twin axes share the height of their zero), phase shading always comes
with its legend, and the force figures have a panel at the scale of the
contact force the experiment is about (about 1 N); the spikes that scale
clips are marked, with the peak value. Each run has its own time axis and is
titled with its method in the paper's words (:func:`method_title`); sweep
keys are named by :func:`key_label` (one mapping for every plot).

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
#: The phases in which the method or the approach law commands a wrench.
COMMANDING = (int(Phase.APPROACH), int(Phase.ALIGN))
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


# -- names ----------------------------------------------------------------------
#: Protocol and scene keys by their names in the paper (mathtext) and their units:
#: the one mapping every plot's axis, title and legend uses (:func:`key_label`).
KEY_LABELS: dict[str, tuple[str, str]] = {
    "align.f_ref[2]": (r"$f_z^\mathrm{ref}$", "N"),
    "align.k_ri[1]": (r"$k_{yp}$", "–"),
    "align.k_ri[3]": (r"$k_{xp}$", "–"),
    "align.kp[2]": (r"$k_{zp}$", "–"),
    "align.ki[2]": (r"$k_{zi}$", "1/s"),
    "approach.speed_mps": ("approach speed", "m/s"),
    "approach.distance_m": ("approach distance", "m"),
    "approach.stiffness[2]": (r"approach stiffness $K_z$", "N/m"),
    "approach.damping[2]": (r"approach damping $D_z$", "N s/m"),
    "scene.target.lateral": ("target lateral offset (Y)", "m"),
    "scene.target.yaw_deg": ("target yaw", "deg"),
    "scene.target.mu": (r"air-bed friction $\mu$", "–"),
    "scene.target.mass": ("target mass", "kg"),
    "scene.target.distance": ("target distance (Z)", "m"),
    "scene.target.hose.stiffness": ("air-hose stiffness", "N/m"),
    "scene.target.hose.damping": ("air-hose damping", "N s/m"),
    "scene.arm.friction_scale": ("joint friction scale", "–"),
    "scene.contact.stiffness": ("contact stiffness", "N/m"),
    "scene.contact.restitution": ("contact restitution $e$", "–"),
    "scene.contact.impedance": ("contact impedance $d$", "–"),
    "scene.contact.friction": ("funnel friction", "–"),
    "scene.fri.command_delay_cycles": ("command delay $d$", "cycles"),
    "scene.ft_sensor.delay_s": ("F/T path delay", "s"),
}
#: Name endings that carry a unit (docs/conventions.md), for keys not in KEY_LABELS.
_SUFFIX_UNITS = (("_mps", "m/s"), ("_deg", "deg"), ("_kg", "kg"), ("_hz", "Hz"),
                 ("_s", "s"), ("_m", "m"), ("_n", "N"))


def key_label(key: str) -> str:
    """How a plot names a protocol or scene key, with its unit: ``align.k_ri[3]`` ->
    ``$k_{xp}$ (–)``; a key not in :data:`KEY_LABELS` keeps its text, with the unit
    its name ends in, if any."""
    if key in KEY_LABELS:
        name, unit = KEY_LABELS[key]
        return f"{name} ({unit})"
    for suffix, unit in _SUFFIX_UNITS:
        if key.endswith(suffix):
            return f"{key.removesuffix(suffix)} ({unit})"
    return key


def key_symbol(key: str) -> str:
    """The key's name without its unit (``$k_{xp}$``), for titles and legends."""
    return KEY_LABELS[key][0] if key in KEY_LABELS else key


def _value(proto: dict[str, Any], key: str) -> float | None:
    """A protocol key's value in a resolved protocol (dict), e.g. ``align.k_ri[3]``."""
    path, _, index = key.partition("[")
    node: Any = proto
    for part in path.split("."):
        node = node.get(part) if isinstance(node, dict) else None
    if index and isinstance(node, list):
        i = int(index.rstrip("]"))
        node = node[i] if i < len(node) else None
    return float(node) if isinstance(node, int | float) and not isinstance(node, bool) else None


def method_title(rec: Recording) -> str:
    """The run's method in the paper's words with its settings, from the recorded
    protocol: ``Method I case I: f_z^ref 0.8 N, k_xp 0.5, k_yp 0.2``.

    The method's name is the head of the protocol's description (``Method I case I``)
    or, when that is a shorter form of it, the registered label (``Method III
    (impedance control)``); the settings are the resolved values (overrides
    included): f_z^ref for a method that tracks it, the inertia-reduction gains
    when the protocol or the paper's values set any."""
    from ffexp import controllers
    from ffexp.analysis import run_info

    info = run_info(rec)
    proto: dict[str, Any] = info.get("protocol_resolved") or {}
    method = str(info.get("method") or proto.get("align", {}).get("method", ""))
    label = controllers.label(method)
    description = str(proto.get("description") or "")
    head = description.split(":", 1)[0].strip() if ":" in description else ""
    name = label if not head or label.startswith(head) else head
    parts = []
    f_ref = _value(proto, "align.f_ref[2]")
    if controllers.tracks_force_reference(method) and f_ref is not None:
        parts.append(f"{key_symbol('align.f_ref[2]')} {f_ref:g} N")
    gains = [(k, _value(proto, k)) for k in ("align.k_ri[3]", "align.k_ri[1]")]
    paper = proto.get("paper") or {}
    if any(v for _k, v in gains) or paper.get("k_xp") or paper.get("k_yp"):
        parts.extend(f"{key_symbol(k)} {v:g}" for k, v in gains if v is not None)
    return f"{name}: {', '.join(parts)}" if parts else name


# -- phases -------------------------------------------------------------------
def shade_phases(ax: Axes, s: RunSeries) -> None:
    """Shade each phase segment of the run (behind the lines)."""
    starts = np.flatnonzero(np.concatenate([[True], s.phase[1:] != s.phase[:-1]]))
    ends = np.concatenate([starts[1:], [len(s.phase) - 1]])
    for a, b in zip(starts, ends, strict=True):
        colour = PHASE_COLOURS.get(Phase(int(s.phase[a])))
        if colour:
            ax.axvspan(s.t_s[a], s.t_s[b], color=colour, lw=0, zorder=0)


def phase_legend(fig: Figure, s_list: Sequence[RunSeries], lines: Sequence[Any] = (),
                 note: str = "") -> None:
    """One legend under the figure: the given line handles (those with a label and
    something drawn), then the phase shading (the phases that occur); ``note`` above
    them (wrapped)."""
    import textwrap

    from matplotlib.patches import Patch

    handles = [h for h in lines if _drawn(h)]
    seen = {int(p) for s in s_list for p in np.unique(s.phase)}
    handles.extend(
        Patch(color=c, label=f"{ph.name} phase")
        for ph, c in PHASE_COLOURS.items() if int(ph) in seen
    )
    if handles:
        ncols = max(1, min(len(handles), int(fig.get_figwidth() // 2.3)))  # fits the width
        fig.legend(handles=handles, loc="outside lower center", ncols=ncols,
                   frameon=False, title="\n".join(textwrap.wrap(note, 150)) or None,
                   title_fontsize=7)


def _drawn(handle: Any) -> bool:
    """A legend handle worth an entry: a label, and for a line some finite data (a
    line without data at all is a legend-only proxy, e.g. :func:`clip_handle`)."""
    label = str(handle.get_label())
    if not label or label.startswith("_"):
        return False
    if hasattr(handle, "get_ydata"):
        y = np.asarray(handle.get_ydata(), dtype=float)
        return y.size == 0 or bool(np.isfinite(y).any())
    return True


def _in_phase(s: RunSeries, values: np.ndarray, phase: Phase) -> np.ndarray:
    """``values`` where the run is in ``phase`` (NaN elsewhere: the line breaks)."""
    out: np.ndarray = np.where(s.phase == phase, values, np.nan)
    return out


def _ref(s: RunSeries) -> np.ndarray:
    """f_ref along Z in ALIGN (NaN elsewhere, and all NaN for a method without one)."""
    if not np.any(s.f_ref[:, 2]):
        return np.full(len(s.t_s), np.nan)
    return _in_phase(s, s.f_ref[:, 2], Phase.ALIGN)


def _zoom_limits(s: RunSeries, commanded: np.ndarray | None = None) -> tuple[float, float]:
    """The y range of the force-scale panel: f_ref (or the ALIGN median) +- max(1 N, 2 f_ref),
    widened to hold the bulk of ``commanded`` (0.5 to 99.5 %, in APPROACH and ALIGN)."""
    f_z = -s.wrench[:, 2]
    in_align = s.phase == Phase.ALIGN
    ref = float(np.nanmedian(s.f_ref[in_align, 2])) if in_align.any() else 0.0
    centre = ref if ref > 0 else (float(np.median(f_z[in_align])) if in_align.any() else 0.0)
    half = max(ZOOM_MIN_N, 2.0 * abs(centre))
    lo, hi = centre - half, centre + half
    if commanded is not None:
        values = commanded[np.isin(s.phase, COMMANDING) & np.isfinite(commanded)]
        if values.size:
            c_lo, c_hi = np.percentile(values, [0.5, 99.5])
            margin = 0.05 * (max(hi, c_hi) - min(lo, c_lo))
            lo, hi = min(lo, c_lo - margin), max(hi, c_hi + margin)
    return float(lo), float(hi)


# -- marks ----------------------------------------------------------------------
#: Values beyond the y range closer than this in time are one spike (one mark).
SPIKE_GAP_S = 0.1
CLIP_COLOUR = "tab:red"


def mark_clipped(ax: Axes, t_s: np.ndarray, y: np.ndarray, unit: str) -> int:
    """Mark the values the axis's y range cuts off: a triangle at the edge for each
    spike (pointing the way it goes), and the largest one's value beside it.
    Returns the number of spikes marked (call after the y range is set)."""
    lo, hi = ax.get_ylim()
    trans = ax.get_xaxis_transform()  # x in data, y in axes fraction
    finite = np.isfinite(y)
    count = 0
    for beyond, edge, marker, dy in ((finite & (y > hi), 0.96, "^", -11),
                                     (finite & (y < lo), 0.04, "v", 4)):
        idx = np.flatnonzero(beyond)
        if not idx.size:
            continue
        groups = np.split(idx, np.flatnonzero(np.diff(t_s[idx]) > SPIKE_GAP_S) + 1)
        peaks = np.array([g[np.argmax(np.abs(y[g]))] for g in groups])
        ax.plot(t_s[peaks], np.full(len(peaks), edge), ls="none", marker=marker, ms=4.5,
                color=CLIP_COLOUR, transform=trans, clip_on=False, zorder=5)
        top = int(peaks[np.argmax(np.abs(y[peaks]))])
        x_lo, x_hi = ax.get_xlim()
        left = (float(t_s[top]) - x_lo) > 0.75 * (x_hi - x_lo)  # the text inside the axes
        ax.annotate(f"peak {y[top]:.3g} {unit}", (float(t_s[top]), edge), xycoords=trans,
                    xytext=(-5 if left else 5, dy), textcoords="offset points", fontsize=7,
                    ha="right" if left else "left", color=CLIP_COLOUR, zorder=6)
        count += len(peaks)
    return count


def clip_handle() -> Any:
    """The legend entry of :func:`mark_clipped`'s marks."""
    from matplotlib.lines import Line2D

    return Line2D([], [], ls="none", marker="^", ms=4.5, color=CLIP_COLOUR,
                  label="beyond the axis (clipped): peak marked")


def align_zeros(ax: Axes, twin: Axes) -> None:
    """Set both y ranges so that their zeros sit at the same height (each range
    still holds all it held, and zero)."""
    lims = [ax.get_ylim(), twin.get_ylim()]
    lims = [(min(lo, 0.0), max(hi, 0.0)) for lo, hi in lims]
    # the height of zero, as a fraction from the bottom: the larger of the two, unless
    # that is the top while the other axis has values above zero (then the middle)
    frac = max(-lo / (hi - lo) if hi > lo else 0.5 for lo, hi in lims)
    if frac >= 1.0 and any(hi > 0.0 for _lo, hi in lims):
        frac = 0.5
    for a, (lo, hi) in zip((ax, twin), lims, strict=True):
        if hi <= lo:
            continue
        need = [-lo / frac if frac > 0 else 0.0, hi / (1.0 - frac) if frac < 1 else 0.0]
        span = max(need)
        a.set_ylim(-frac * span, (1.0 - frac) * span)


def _approach_note(rec: Recording) -> str:
    """What the command is in APPROACH (from the recorded protocol's approach law)."""
    from ffexp.analysis import run_info

    proto: dict[str, Any] = run_info(rec).get("protocol_resolved") or {}
    k = _value(proto, "approach.stiffness[2]")
    d = _value(proto, "approach.damping[2]")
    v = _value(proto, "approach.speed_mps")
    law = "" if k is None else (
        f" ($K_z$ {k:g} N/m" + (f", $D_z$ {d:g} N s/m" if d is not None else "")
        + (f", set-point moving at {v:g} m/s" if v is not None else "") + ")")
    return ("In APPROACH the commanded force is the approach impedance law" + law
            + ": in free space it swings as the arm lags and overshoots the moving "
            "set-point. It is no contact force; in ALIGN the method commands.")


# -- run figures --------------------------------------------------------------
def _titled(fig: Figure, rec: Recording, what: str) -> None:
    fig.suptitle(f"{method_title(rec)}\n{what}")


def wrench_figure(rec: Recording, title: str) -> Figure:
    """Measured contact wrench (the paper's exp_all_wrench, one run): f_z at full
    scale and at the force scale (clipped spikes marked), lateral forces, torque
    about X; one unit per axis. ``title``: the run's name (printed above the legend)."""
    from ffexp.analysis import series

    s = series(rec)
    fig = new_figure(7.5, 7.8)
    axes = fig.subplots(4, 1, sharex=True)
    f_z = -s.wrench[:, 2]
    for ax in axes:
        shade_phases(ax, s)
        ax.set_xlim(float(s.t_s[0]), float(s.t_s[-1]))
    ax = axes[0]
    (l_fz,) = ax.plot(s.t_s, f_z, label="$f_z = -w_z$ (contact; pushing > 0)")
    (l_ref,) = ax.plot(s.t_s, _ref(s), "k--", label=r"$f_z^\mathrm{ref}$")
    ax.set_ylabel("f_z [N]\n(full scale)")
    ax = axes[1]
    ax.plot(s.t_s, f_z)
    ax.plot(s.t_s, _ref(s), "k--")
    ax.set_ylim(*_zoom_limits(s))
    clipped = mark_clipped(ax, s.t_s, f_z, "N")
    ax.set_ylabel("f_z [N]\n(force scale)")
    ax = axes[2]
    (l_y,) = ax.plot(s.t_s, s.wrench[:, 1], color="tab:orange", label="$w_y$ (lateral)")
    (l_x,) = ax.plot(s.t_s, s.wrench[:, 0], color="tab:gray", lw=0.7, label="$w_x$ (vertical)")
    ax.set_ylabel("force [N]")
    ax = axes[3]
    (l_t,) = ax.plot(s.t_s, s.wrench[:, 3], color="tab:green", label=r"$t_x$ (about X)")
    ax.set_ylabel("torque X [N m]")
    ax.set_xlabel("time since the run's start [s]")
    lines = [l_fz, l_ref, *([clip_handle()] if clipped else []), l_y, l_x, l_t]
    phase_legend(fig, [s], lines, note=f"run {title}")
    _titled(fig, rec, "measured contact wrench (TCF, environment on tool)")
    return fig


def applied_figure(rec: Recording, title: str) -> Figure:
    """f_z; contact vs applied force along Y; contact vs applied torque about X
    (the paper's exp_fc_tri, exp_fc_ti_1 and exp_fc). The command is drawn by
    phase: APPROACH's impedance law apart from the method's command in ALIGN."""
    from ffexp.analysis import series

    s = series(rec)
    fig = new_figure(12.0, 4.4)
    axes = fig.subplots(1, 3)
    panels = [
        ("(a) contact force along Z", -s.wrench[:, 2], s.applied[:, 2], "f_z [N]", "N"),
        ("(b) force along Y", s.wrench[:, 1], s.applied[:, 1], "f_y [N]", "N"),
        ("(c) torque about X", s.wrench[:, 3], s.applied[:, 3], "t_x [N m]", "N m"),
    ]
    handles: list[Any] = []
    for ax, (name, contact, applied, label, unit) in zip(axes, panels, strict=True):
        shade_phases(ax, s)
        ax.set_xlim(float(s.t_s[0]), float(s.t_s[-1]))
        lines = [
            ax.plot(s.t_s, contact, label="contact (measured)")[0],
            ax.plot(s.t_s, _in_phase(s, applied, Phase.APPROACH), color="0.45", ls=":",
                    lw=1.1, label="commanded in APPROACH (approach law)")[0],
            ax.plot(s.t_s, _in_phase(s, applied, Phase.ALIGN), color="tab:orange",
                    label="commanded in ALIGN (the method)")[0],
        ]
        if name.startswith("(a)"):
            lines.append(ax.plot(s.t_s, _ref(s), "k--", label=r"$f_z^\mathrm{ref}$")[0])
            ax.set_ylim(*_zoom_limits(s, commanded=applied))
            clipped = mark_clipped(ax, s.t_s, contact, unit)
            commanded = np.where(np.isin(s.phase, COMMANDING), applied, np.nan)
            if clipped + mark_clipped(ax, s.t_s, commanded, unit):
                lines.append(clip_handle())
            ax.set_title(name + " (force scale)")
            handles = lines
        else:
            ax.set_title(name)
        ax.set_xlabel("time since the run's start [s]")
        ax.set_ylabel(label)
    phase_legend(fig, [s], handles, note=f"run {title}. {_approach_note(rec)}")
    _titled(fig, rec, "contact and commanded wrench")
    return fig


def campaign_figure(recs: Sequence[tuple[str, Recording]], title: str) -> Figure:
    """One row per run, each on its own time axis and titled with its method: f_z at
    the force scale (clipped spikes marked); lateral force and torque about X on twin
    axes with one zero. ``recs``: (name printed small beside the title, recording)."""
    from ffexp.analysis import series

    n = len(recs)
    fig = new_figure(11.0, 2.0 * n + 1.3)
    axes = np.atleast_2d(fig.subplots(n, 2, squeeze=False))
    seen = []
    handles: dict[str, Any] = {}
    for row, (name, rec) in zip(axes, recs, strict=True):
        s = series(rec)
        seen.append(s)
        ax_f, ax_l = row
        ax_l.sharex(ax_f)
        f_z = -s.wrench[:, 2]
        for ax in row:
            shade_phases(ax, s)
            ax.set_xlim(float(s.t_s[0]), float(s.t_s[-1]))
            ax.set_xlabel("time since the run's start [s]")
        lines = [ax_f.plot(s.t_s, f_z, label="$f_z$ (contact, force scale)")[0],
                 ax_f.plot(s.t_s, _ref(s), "k--", label=r"$f_z^\mathrm{ref}$")[0]]
        ax_f.set_ylim(*_zoom_limits(s))
        if mark_clipped(ax_f, s.t_s, f_z, "N"):
            lines.append(clip_handle())
        ax_f.set_ylabel("f_z [N]")
        ax_f.set_title(method_title(rec), loc="left")
        lines.append(ax_l.plot(s.t_s, s.wrench[:, 1], color="tab:orange",
                               label="$w_y$ (lateral force, left axis)")[0])
        ax_l.set_ylabel("w_y [N]", color="tab:orange")
        ax_t = ax_l.twinx()
        lines.append(ax_t.plot(s.t_s, s.wrench[:, 3], color="tab:green",
                               label="$t_x$ (torque about X, right axis)")[0])
        ax_t.set_ylabel("t_x [N m]", color="tab:green")
        ax_t.grid(False)
        align_zeros(ax_l, ax_t)
        ax_l.axhline(0.0, color="0.3", lw=0.6, zorder=1)
        ax_l.set_title(f"lateral wrench (TCF), run {name}", loc="left", fontsize=7,
                       color="0.3")
        for line in lines:
            if _drawn(line):
                handles.setdefault(str(line.get_label()), line)
    phase_legend(fig, seen, list(handles.values()))
    fig.suptitle(f"{title}: contact force at the force scale; lateral wrench (TCF)")
    return fig


def write_run_figures(rec: Recording, out_dir: Path, name: str) -> list[Path]:
    """The per-run figures (PNG and SVG) as ``<name>_wrench`` and ``<name>_applied``."""
    paths: list[Path] = []
    with style():
        for suffix, make in (("wrench", wrench_figure), ("applied", applied_figure)):
            paths.extend(save(make(rec, name), out_dir, f"{name}_{suffix}"))
    return paths
