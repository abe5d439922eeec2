"""Figures of sweeps (PNG): heat maps over two keys, lines over one, limit searches,
the paper check. In the style of :mod:`ffexp.figures`; matplotlib is imported by it."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.figure import Figure

#: The three outcomes a sweep figure shows: (column, title, aggregation).
OUTCOMES: tuple[tuple[str, str], ...] = (
    ("aligned", "aligned fraction"),
    ("contact_breaks", "contact breaks (mean)"),
    ("mean_fz_align_n", "mean f_z in ALIGN [N] (mean)"),
)


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


def sweep_figures(df: pd.DataFrame, keys: Sequence[str], out_dir: Path, title: str) -> list[Path]:
    """Heat maps for the first two varied keys, line plots for one (means over the
    seeds and any further keys); nothing without a varied key."""
    from ffexp import figures

    keys = [k for k in keys if k in df]
    if not keys:
        return []
    data = df[list(keys)].copy()
    for col, _ in OUTCOMES:
        data[col] = _numeric(df, col)
    with figures.style():
        if len(keys) == 1:
            fig = _lines(data, keys[0], title)
            return [_save_png(fig, out_dir / "lines.png")]
        fig = _heatmaps(data, keys[0], keys[1], title, more=len(keys) > 2)
        return [_save_png(fig, out_dir / "heatmap.png")]


def _lines(data: pd.DataFrame, key: str, title: str) -> Figure:
    from ffexp.figures import new_figure

    grouped = data.groupby(key, sort=True)
    fig = new_figure(4.0 * len(OUTCOMES), 3.0)
    axes = fig.subplots(1, len(OUTCOMES))
    for ax, (col, label) in zip(axes, OUTCOMES, strict=True):
        mean = grouped[col].mean()
        ax.plot(mean.index, mean.to_numpy(), marker="o")
        ax.scatter(data[key], data[col], s=8, color="0.5", zorder=0, label="runs")
        ax.set_xlabel(key)
        ax.set_title(label)
    axes[0].set_ylim(-0.05, 1.05)
    fig.suptitle(title)
    return fig


def _heatmaps(data: pd.DataFrame, kx: str, ky: str, title: str, more: bool) -> Figure:
    from ffexp.figures import new_figure

    fig = new_figure(4.2 * len(OUTCOMES), 3.4)
    axes = fig.subplots(1, len(OUTCOMES))
    for ax, (col, label) in zip(axes, OUTCOMES, strict=True):
        table = data.pivot_table(index=ky, columns=kx, values=col, aggfunc="mean",
                                 dropna=False)
        values = table.to_numpy(dtype=float)
        limits: dict[str, Any] = {"vmin": 0.0, "vmax": 1.0} if col == "aligned" else {}
        im = ax.imshow(values, origin="lower", aspect="auto", cmap="viridis", **limits)
        ax.set_xticks(range(len(table.columns)), [f"{v:.4g}" if isinstance(v, float) else str(v)
                                                  for v in table.columns], rotation=45)
        ax.set_yticks(range(len(table.index)), [f"{v:.4g}" if isinstance(v, float) else str(v)
                                                for v in table.index])
        for (i, j), v in _cells(values):
            ax.text(j, i, f"{v:.2g}", ha="center", va="center", fontsize=7, color="w")
        ax.set_xlabel(kx)
        ax.set_ylabel(ky)
        ax.set_title(label + (" (mean over the other keys)" if more else ""))
        ax.grid(False)
        fig.colorbar(im, ax=ax, shrink=0.85)
    fig.suptitle(title)
    return fig


def _cells(values: Any) -> list[tuple[tuple[int, int], float]]:
    import numpy as np

    return [((int(i), int(j)), float(values[i, j]))
            for i, j in zip(*np.nonzero(np.isfinite(values)), strict=True)]


def limits_figure(
    points: Sequence[tuple[Sequence[float], float]], keys: Sequence[str],
    boundary: Sequence[Sequence[float]], title: str, path: Path,
) -> Path:
    """Outcome (aligned fraction) against the key, or over the plane of two keys with
    the boundary points found."""
    from ffexp import figures
    from ffexp.figures import new_figure

    with figures.style():
        fig = new_figure(5.0, 3.6)
        ax = fig.subplots()
        xs = [p[0][0] for p in points]
        frac = [p[1] for p in points]
        if len(keys) == 1:
            order = sorted(range(len(xs)), key=lambda i: xs[i])
            ax.plot([xs[i] for i in order], [frac[i] for i in order], marker="o")
            for b in boundary:
                ax.axvline(b[0], color="C3", linestyle="--")
            ax.set_xlabel(keys[0])
            ax.set_ylabel("aligned fraction (over seeds)")
            ax.set_ylim(-0.05, 1.05)
        else:
            ys = [p[0][1] for p in points]
            sc = ax.scatter(xs, ys, c=frac, cmap="viridis", vmin=0.0, vmax=1.0, s=14)
            if boundary:
                ax.plot([b[0] for b in boundary], [b[1] for b in boundary], "C3x",
                        label="boundary")
                ax.legend(loc="best")
            fig.colorbar(sc, ax=ax, label="aligned fraction")
            ax.set_xlabel(keys[0])
            ax.set_ylabel(keys[1])
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


def scene_map(
    scenes: pd.DataFrame, keys: Sequence[str], columns: Sequence[str], title: str, path: Path
) -> Path | None:
    """Each outcome (a run's aligned flag, a claim) over the first two scene keys: one
    square per scene point, coloured by the fraction over seeds and further keys (a
    grid shows where an outcome flips between neighbours). None with fewer than two keys
    or without varied scenes."""
    from ffexp import figures
    from ffexp.figures import new_figure

    keys = [k for k in keys if k in scenes]
    data = scenes.dropna(subset=keys[:2]) if len(keys) >= 2 else scenes.iloc[0:0]
    if data.empty:
        return None
    kx, ky = keys[0], keys[1]
    cols = [c for c in columns if c in data]
    with figures.style():
        ncol = min(3, len(cols))
        nrow = -(-len(cols) // ncol)
        fig = new_figure(3.6 * ncol, 3.0 * nrow)
        axes = fig.subplots(nrow, ncol, squeeze=False).ravel()
        for ax, col in zip(axes, cols, strict=False):
            values = data[col].astype("Float64").astype("float64")
            mean = values.groupby([data[kx], data[ky]]).mean().reset_index()
            sc = ax.scatter(mean[kx], mean[ky], c=mean[col], cmap="RdYlGn", vmin=0.0,
                            vmax=1.0, marker="s", s=120, edgecolors="0.3")
            ax.set_title(col)
            ax.set_xlabel(kx)
            ax.set_ylabel(ky)
        for ax in axes[len(cols):]:
            ax.set_visible(False)
        fig.colorbar(sc, ax=list(axes[:len(cols)]), shrink=0.8,
                     label="fraction (seeds, further keys)")
        fig.suptitle(title)
        return _save_png(fig, path)
