"""Figures of sweeps (PNG): heat maps over two keys, lines over one, limit searches,
the paper check. In the style of :mod:`ffexp.figures`; matplotlib is imported by it.

Keys are named by :func:`ffexp.figures.key_label` (the paper's names, with units).
Where the caller gives the nominal values (:func:`nominal_values`: the protocol's
and scene's own values), every figure marks them: the nominal point on maps, a
line on plots over one key.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.figure import Figure

    from ffexp.sweeps.keys import Key
    from ffexp.sweeps.plan import Target

#: The three outcomes a sweep figure shows: (column, title).
OUTCOMES: tuple[tuple[str, str], ...] = (
    ("aligned", "aligned fraction (–)"),
    ("contact_breaks", "contact breaks in ALIGN (mean count)"),
    ("mean_fz_align_n", r"mean $f_z$ in ALIGN (N)"),
)
NOMINAL_STYLE: dict[str, Any] = {"marker": "*", "s": 160, "facecolors": "white",
                                 "edgecolors": "black", "linewidths": 1.0, "zorder": 6}
NOMINAL_CELL: dict[str, Any] = {"fill": False, "edgecolor": "black", "linewidth": 2.0,
                                "zorder": 6}
NOMINAL_EDGE: dict[str, Any] = {"s": 70, "facecolors": "white", "edgecolors": "black",
                                "linewidths": 1.0, "zorder": 6, "clip_on": False}
NOMINAL_LABEL = "nominal (the protocol's and scene's own values)"


def nominal_values(target: Target, keys: Sequence[Key]) -> dict[str, float]:
    """The nominal value of each numeric key: its value in the target's resolved
    protocol and scene (what the figures mark as nominal)."""
    from ffexp.errors import ConfigError
    from ffexp.sweeps.keys import current_value

    proto = target.protocol.model_dump(mode="json")
    scene = target.scene.model_dump(mode="json")
    out: dict[str, float] = {}
    for key in keys:
        try:
            value = current_value(key, proto, scene)
        except ConfigError:
            continue
        if isinstance(value, int | float) and not isinstance(value, bool):
            out[key.text] = float(value)
    return out


def _save_png(fig: Figure, path: Path) -> Path:
    from ffexp.figures import DPI

    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp.png")
    fig.savefig(tmp, dpi=DPI)
    tmp.replace(path)
    return path


def _numeric(df: pd.DataFrame, col: str) -> pd.Series:
    import pandas as pd

    if col not in df:
        return pd.Series([float("nan")] * len(df), index=df.index, dtype="float64")
    return pd.to_numeric(df[col].astype("Float64"), errors="coerce").astype("float64")


def sweep_figures(df: pd.DataFrame, keys: Sequence[str], out_dir: Path, title: str,
                  nominal: Mapping[str, float] | None = None) -> list[Path]:
    """Heat maps for the first two varied keys, line plots for one (means over the
    seeds and any further keys); nothing without a varied key."""
    from ffexp import figures

    keys = [k for k in keys if k in df]
    if not keys:
        return []
    data = df[list(keys)].copy()
    for col, _ in OUTCOMES:
        data[col] = _numeric(df, col)
    nominal = nominal or {}
    with figures.style():
        if len(keys) == 1:
            fig = _lines(data, keys[0], title, nominal.get(keys[0]))
            return [_save_png(fig, out_dir / "lines.png")]
        fig = _heatmaps(data, keys[0], keys[1], title, keys[2:], nominal)
        return [_save_png(fig, out_dir / "heatmap.png")]


def _lines(data: pd.DataFrame, key: str, title: str, nominal: float | None) -> Figure:
    from ffexp.figures import key_label, new_figure

    grouped = data.groupby(key, sort=True)
    fig = new_figure(4.0 * len(OUTCOMES), 3.2)
    axes = fig.subplots(1, len(OUTCOMES))
    for ax, (col, label) in zip(axes, OUTCOMES, strict=True):
        mean = grouped[col].mean()
        ax.plot(mean.index, mean.to_numpy(), marker="o", label="mean over seeds")
        ax.scatter(data[key], data[col], s=8, color="0.5", zorder=0, label="runs")
        if nominal is not None:
            ax.axvline(nominal, color="black", ls="--", lw=0.8, label="nominal")
        ax.set_xlabel(key_label(key))
        ax.set_ylabel(label)
        ax.set_title(label)
    axes[0].set_ylim(-0.05, 1.05)
    axes[0].legend(loc="best")
    fig.suptitle(title)
    return fig


def _tick(v: object) -> str:
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def _position(values: Sequence[Any], x: float | None) -> float | None:
    """Where value ``x`` sits on an axis of cells at 0, 1, ... holding ``values``
    (sorted numbers): interpolated between cells; None outside or not numeric."""
    import numpy as np

    try:
        v = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        return None
    if x is None or not len(v) or not v[0] <= x <= v[-1]:
        return None
    return float(np.interp(x, v, np.arange(len(v))))


def _heatmaps(data: pd.DataFrame, kx: str, ky: str, title: str, more: Sequence[str],
              nominal: Mapping[str, float]) -> Figure:
    import numpy as np
    from matplotlib.colors import Normalize

    from ffexp.figures import key_label, new_figure

    fig = new_figure(4.3 * len(OUTCOMES), 3.8)
    axes = fig.subplots(1, len(OUTCOMES))
    marked = ""
    for ax, (col, label) in zip(axes, OUTCOMES, strict=True):
        table = data.pivot_table(index=ky, columns=kx, values=col, aggfunc="mean",
                                 dropna=False)
        values = table.to_numpy(dtype=float)
        finite = values[np.isfinite(values)]
        lo, hi = (0.0, 1.0) if col == "aligned" or not finite.size else (
            float(finite.min()), float(finite.max()))
        if hi <= lo:  # one value everywhere: a scale around it, not a fake range
            lo, hi = lo - 0.5, hi + 0.5
        norm = Normalize(lo, hi)
        im = ax.imshow(values, origin="lower", aspect="auto", cmap="viridis", norm=norm)
        ax.set_xticks(range(len(table.columns)), [_tick(v) for v in table.columns],
                      rotation=45)
        ax.set_yticks(range(len(table.index)), [_tick(v) for v in table.index])
        for (i, j), v in _cells(values):
            dark = norm(v) < 0.6  # viridis: dark below, light above
            ax.text(j, i, f"{v:.2g}", ha="center", va="center", fontsize=7,
                    color="white" if dark else "black")
        x0 = _position(list(table.columns), nominal.get(kx))
        y0 = _position(list(table.index), nominal.get(ky))
        if x0 is not None and y0 is not None:
            marked = _mark_nominal(ax, x0, y0) or marked
        ax.set_xlabel(key_label(kx))
        ax.set_ylabel(key_label(ky))
        ax.set_title(label)
        ax.grid(False)
        fig.colorbar(im, ax=ax, shrink=0.85)
    if marked:
        fig.legend(handles=[_NOMINAL_HANDLES[marked]()], loc="outside lower center",
                   frameon=False)
    if more:
        title += "\n(mean over " + ", ".join(key_label(k) for k in more) + ")"
    fig.suptitle(title)
    return fig


def _mark_nominal(ax: Any, x0: float, y0: float) -> str:
    """Mark the nominal point at cell coordinates ``(x0, y0)`` without covering any cell's
    number: on a cell, a frame along that cell's edges; between cells, a pointer on each
    axis's spines at its position (inside the map any mark would cross a number). Returns
    which mark ("cell" or "edges")."""
    from matplotlib.patches import Rectangle

    if abs(x0 - round(x0)) < 1e-9 and abs(y0 - round(y0)) < 1e-9:
        ax.add_patch(Rectangle((round(x0) - 0.5, round(y0) - 0.5), 1.0, 1.0, **NOMINAL_CELL))
        return "cell"
    xs, ys = ax.get_xlim(), ax.get_ylim()
    for px, py, marker in ((x0, min(ys), "^"), (x0, max(ys), "v"),
                           (min(xs), y0, ">"), (max(xs), y0, "<")):
        ax.scatter([px], [py], marker=marker, **NOMINAL_EDGE)
    ax.set_xlim(xs)
    ax.set_ylim(ys)
    return "edges"


def _edge_handle() -> Any:
    from matplotlib.lines import Line2D

    return Line2D([], [], ls="", marker="^", markersize=8, markerfacecolor="white",
                  markeredgecolor="black", label=NOMINAL_LABEL + ", between cells")


def _cell_handle() -> Any:
    from matplotlib.patches import Rectangle

    return Rectangle((0, 0), 1, 1, label=NOMINAL_LABEL, **NOMINAL_CELL)


_NOMINAL_HANDLES = {"cell": _cell_handle, "edges": _edge_handle}


def _cells(values: Any) -> list[tuple[tuple[int, int], float]]:
    import numpy as np

    return [((int(i), int(j)), float(values[i, j]))
            for i, j in zip(*np.nonzero(np.isfinite(values)), strict=True)]


def limits_figure(
    points: Sequence[tuple[Sequence[float], float]], keys: Sequence[str],
    boundary: Sequence[Sequence[float]], title: str, path: Path,
    nominal: Mapping[str, float] | None = None,
) -> Path:
    """Outcome (aligned fraction) against the key, or over the plane of two keys with
    the boundary points found."""
    from ffexp import figures
    from ffexp.figures import key_label, key_symbol, new_figure

    nominal = nominal or {}
    for key in keys:  # the paper's names in the caller's title too
        title = title.replace(key, key_symbol(key))
    with figures.style():
        fig = new_figure(5.4, 3.9)
        ax = fig.subplots()
        xs = [p[0][0] for p in points]
        frac = [p[1] for p in points]
        if len(keys) == 1:
            order = sorted(range(len(xs)), key=lambda i: xs[i])
            ax.plot([xs[i] for i in order], [frac[i] for i in order], marker="o",
                    label="runs looked at")
            for i, b in enumerate(boundary):
                ax.axvline(b[0], color="C3", linestyle="--",
                           label="limit found" if i == 0 else "_limit")
            if keys[0] in nominal:
                ax.axvline(nominal[keys[0]], color="black", lw=0.8, ls=":", label="nominal")
            ax.set_xlabel(key_label(keys[0]))
            ax.set_ylabel("aligned fraction over seeds (–)")
            ax.set_ylim(-0.05, 1.05)
        else:
            ys = [p[0][1] for p in points]
            sc = ax.scatter(xs, ys, c=frac, cmap="viridis", vmin=0.0, vmax=1.0, s=14,
                            label="runs looked at")
            if boundary:
                ax.plot([b[0] for b in boundary], [b[1] for b in boundary], "C3x",
                        label="boundary found")
            if keys[0] in nominal and keys[1] in nominal:
                ax.scatter([nominal[keys[0]]], [nominal[keys[1]]], label="nominal",
                           **NOMINAL_STYLE)
            fig.colorbar(sc, ax=ax, label="aligned fraction over seeds (–)")
            ax.set_xlabel(key_label(keys[0]))
            ax.set_ylabel(key_label(keys[1]))
        if len(keys) == 1:
            ax.legend(loc="best", fontsize=7)
        else:  # below the plane: the points fill it
            handles, labels = ax.get_legend_handles_labels()
            fig.legend(handles, labels, loc="outside lower center", ncols=3, fontsize=7,
                       frameon=False)
        ax.set_title(title)
        return _save_png(fig, path)


def claims_figure(summary: Sequence[dict[str, Any]], title: str, path: Path) -> Path:
    """Fraction of scenes where each claim holds (bars)."""
    from ffexp import figures
    from ffexp.figures import new_figure

    with figures.style():
        fig = new_figure(6.5, 0.45 * max(3, len(summary)) + 1.0)
        ax = fig.subplots()
        names = [str(s["claim"]) for s in summary]
        values = [float(s["fraction"]) if s["fraction"] is not None else 0.0 for s in summary]
        ax.barh(range(len(names)), values, color="C0")
        ax.set_yticks(range(len(names)), names)
        ax.invert_yaxis()
        ax.set_xlim(0.0, 1.0)
        ax.set_xlabel("fraction of scenes where the claim holds")
        for i, s in enumerate(summary):
            ax.text(min(values[i] + 0.02, 0.9), i, f"{s['holds']}/{s['scenes']}", va="center")
        ax.set_title(title)
        return _save_png(fig, path)


def deciding_keys(data: pd.DataFrame, keys: Sequence[str], columns: Sequence[str],
                  nominal: Mapping[str, float] | None = None) -> list[tuple[str, float]]:
    """The keys that vary in ``data``, most deciding first, each with its score: the
    largest |Spearman rank correlation| between the key (or its distance from the
    nominal value, for an outcome that flips on both sides) and any outcome column
    that varies. Keys that never vary are left out; ties keep the plan's order."""
    nominal = nominal or {}
    outcomes = [data[c].astype("Float64").astype("float64") for c in columns if c in data]
    outcomes = [o for o in outcomes if o.nunique(dropna=True) > 1]
    scored = []
    for key in keys:
        if key not in data:
            continue
        x = data[key].astype("Float64").astype("float64")
        if x.nunique(dropna=True) < 2:
            continue
        forms = [x] + ([(x - nominal[key]).abs()] if key in nominal else [])
        score = 0.0
        for o in outcomes:
            for f in forms:
                rho = f.rank().corr(o.rank())
                if rho == rho:  # not NaN
                    score = max(score, abs(float(rho)))
        scored.append((key, score))
    return sorted(scored, key=lambda ks: -ks[1])  # stable: ties keep the plan's order


def scene_map(
    scenes: pd.DataFrame, keys: Sequence[str], columns: Sequence[str], title: str, path: Path,
    nominal: Mapping[str, float] | None = None,
) -> Path | None:
    """Each outcome (a run's aligned flag, a claim) over the two scene keys that decide
    the outcomes most (:func:`deciding_keys`; one key: a strip per outcome): one square
    per scene, coloured by the fraction over seeds and the keys not drawn. The
    nominal scene (its keys unset in ``scenes``) is drawn at ``nominal`` and marked.
    None without a key that varies."""
    import textwrap

    from ffexp import figures
    from ffexp.figures import key_label

    nominal = dict(nominal or {})
    data = scenes.copy()
    for key in keys:  # the nominal scene: no overrides, its keys at their own values
        if key in data and key in nominal:
            data[key] = data[key].astype("object").where(data[key].notna(), nominal[key])
    ranked = deciding_keys(data, keys, columns, nominal)
    if not ranked:
        return None
    drawn = [k for k, _s in ranked[:2]]
    data = data.dropna(subset=drawn)
    cols = [c for c in columns if c in data]
    if data.empty or not cols:
        return None
    rest = ", ".join(f"{key_label(k)} {s:.2f}" for k, s in ranked[2:])
    note = ("drawn over the keys that decide most (|rank correlation| with the outcomes): "
            + ", ".join(f"{key_label(k)} {s:.2f}" for k, s in ranked[:2])
            + (f"; averaged over: {rest}" if rest else ""))
    with figures.style():
        if len(drawn) == 1:
            fig = _strip_map(data, drawn[0], cols, nominal.get(drawn[0]))
        else:
            fig = _pair_map(data, drawn[0], drawn[1], cols, nominal)
        width = int(fig.get_figwidth() * 11)  # characters that fit the figure's width
        fig.suptitle("\n".join([title, *textwrap.wrap(note, width)]))
        return _save_png(fig, path)


def _pair_map(data: pd.DataFrame, kx: str, ky: str, cols: Sequence[str],
              nominal: Mapping[str, float]) -> Figure:
    from ffexp.figures import key_label, new_figure

    ncol = min(3, len(cols))
    nrow = -(-len(cols) // ncol)
    fig = new_figure(3.8 * ncol, 3.2 * nrow + 0.6)
    axes = fig.subplots(nrow, ncol, squeeze=False).ravel()
    sc = None
    for ax, col in zip(axes, cols, strict=False):
        values = data[col].astype("Float64").astype("float64")
        mean = values.groupby([data[kx].astype(float), data[ky].astype(float)]).mean()
        mean = mean.reset_index()
        sc = ax.scatter(mean[kx], mean[ky], c=mean[col], cmap="RdYlGn", vmin=0.0,
                        vmax=1.0, marker="s", s=120, edgecolors="0.3")
        if kx in nominal and ky in nominal:
            ax.scatter([nominal[kx]], [nominal[ky]], marker="o", s=240, facecolors="none",
                       edgecolors="black", linewidths=1.4, zorder=6, label="nominal scene")
        ax.set_title(col)
        ax.set_xlabel(key_label(kx))
        ax.set_ylabel(key_label(ky))
    for ax in axes[len(cols):]:
        ax.set_visible(False)
    if kx in nominal and ky in nominal:
        handles, labels = axes[0].get_legend_handles_labels()
        fig.legend(handles, labels, loc="outside lower center", frameon=False)
    if sc is not None:
        fig.colorbar(sc, ax=list(axes[:len(cols)]), shrink=0.8,
                     label="fraction (seeds, keys not drawn)")
    return fig


def _strip_map(data: pd.DataFrame, key: str, cols: Sequence[str],
               nominal: float | None) -> Figure:
    import numpy as np

    from ffexp.figures import key_label, new_figure

    fig = new_figure(7.0, 0.45 * len(cols) + 1.6)
    ax = fig.subplots()
    sc = None
    for i, col in enumerate(cols):
        values = data[col].astype("Float64").astype("float64")
        mean = values.groupby(data[key].astype(float)).mean()
        sc = ax.scatter(mean.index, np.full(len(mean), i), c=mean.to_numpy(), cmap="RdYlGn",
                        vmin=0.0, vmax=1.0, marker="s", s=110, edgecolors="0.3")
    if nominal is not None:
        ax.axvline(nominal, color="black", ls="--", lw=0.8, label="nominal scene")
        ax.legend(loc="upper right", fontsize=7)
    ax.set_yticks(range(len(cols)), list(cols))
    ax.invert_yaxis()
    ax.set_xlabel(key_label(key))
    if sc is not None:
        fig.colorbar(sc, ax=ax, label="fraction (seeds)")
    return fig
