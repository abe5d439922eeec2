"""Sweep, limits and reproduce figures: keys by their paper names, the nominal point
marked, and the reproduce map drawn over the keys that decide the outcomes (found
from the scenes, not from the order the keys were given in)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from ffexp.sweeps import plots

KEYS = ["scene.target.mu", "scene.arm.friction_scale", "scene.target.yaw_deg",
        "scene.target.lateral"]
NOMINAL = {"scene.target.mu": 0.005, "scene.arm.friction_scale": 1.0,
           "scene.target.yaw_deg": 8.0, "scene.target.lateral": 0.012}


def scenes(n: int = 24) -> pd.DataFrame:
    """Scenes whose outcome is decided by the yaw (aligned below 9 deg) and by the
    lateral offset's distance from nominal; friction varies and decides nothing; the
    joint friction never varies. Row 0 is the nominal scene (keys unset)."""
    rng = np.random.default_rng(0)
    rows: list[dict[str, Any]] = [{"scene": 0, **dict.fromkeys(KEYS), "seed": 1}]
    for i in range(1, n):
        rows.append({"scene": i, "scene.target.mu": float(rng.uniform(0.002, 0.009)),
                     "scene.arm.friction_scale": 1.0,
                     "scene.target.yaw_deg": float(rng.uniform(6.5, 9.5)),
                     "scene.target.lateral": float(rng.uniform(0.008, 0.016)), "seed": 1})
    frame = pd.DataFrame(rows)
    yaw = frame["scene.target.yaw_deg"].fillna(8.0)
    lat = (frame["scene.target.lateral"].fillna(0.012) - 0.012).abs()
    frame["I-1 aligned"] = yaw < 9.0
    frame["ordering"] = lat < 0.002
    return frame


def captured(monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    figs: list[Any] = []
    monkeypatch.setattr(plots, "_save_png", lambda fig, path: figs.append(fig) or path)
    return figs


def test_deciding_keys_found_from_the_outcomes_not_the_key_order() -> None:
    frame = scenes()
    ranked = plots.deciding_keys(frame, KEYS, ["I-1 aligned", "ordering"], NOMINAL)
    names = [k for k, _s in ranked]
    assert "scene.arm.friction_scale" not in names  # it never varies
    assert set(names[:2]) == {"scene.target.yaw_deg", "scene.target.lateral"}
    assert names[2] == "scene.target.mu"
    # the lateral offset decides on both sides of nominal: its distance from the
    # nominal value shows it better than its value alone
    with_nominal = dict(plots.deciding_keys(frame, KEYS, ["ordering"], NOMINAL))
    alone = dict(plots.deciding_keys(frame, KEYS, ["ordering"]))
    assert with_nominal["scene.target.lateral"] > alone["scene.target.lateral"] + 0.3


def test_scene_map_over_the_deciding_keys_with_the_nominal_scene(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    figs = captured(monkeypatch)
    path = plots.scene_map(scenes(), KEYS, ["I-1 aligned", "ordering"], "t",
                           tmp_path / "s.png", nominal=NOMINAL)
    assert path == tmp_path / "s.png"
    (fig,) = figs
    ax = fig.axes[0]
    assert {ax.get_xlabel(), ax.get_ylabel()} == {"target yaw (deg)",
                                                  "target lateral offset (Y) (m)"}
    nominal = [c for c in ax.collections if c.get_label() == "nominal scene"]
    assert len(nominal) == 1
    x_key = "scene.target.yaw_deg" if ax.get_xlabel() == "target yaw (deg)" else (
        "scene.target.lateral")
    y_key = next(k for k in ("scene.target.yaw_deg", "scene.target.lateral") if k != x_key)
    assert tuple(nominal[0].get_offsets()[0]) == pytest.approx((NOMINAL[x_key], NOMINAL[y_key]))
    squares = ax.collections[0].get_offsets()
    assert len(squares) == len(scenes())  # the nominal scene is drawn too
    assert "nominal scene" in [t.get_text() for leg in fig.legends for t in leg.get_texts()]


def test_scene_map_with_one_deciding_key_is_a_strip(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    figs = captured(monkeypatch)
    frame = scenes().drop(columns=["scene.target.mu", "scene.target.lateral"])
    assert plots.scene_map(frame, KEYS, ["I-1 aligned"], "t", tmp_path / "s.png",
                           nominal=NOMINAL) is not None
    ax = figs[0].axes[0]
    assert ax.get_xlabel() == "target yaw (deg)"
    assert [t.get_text() for t in ax.get_yticklabels()] == ["I-1 aligned"]
    constant = scenes().assign(**{k: 1.0 for k in KEYS})
    assert plots.scene_map(constant, KEYS, ["I-1 aligned"], "t", tmp_path / "n.png") is None


def test_sweep_heatmap_names_keys_and_frames_the_nominal_cell(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    figs = captured(monkeypatch)
    grid = [(k, f) for k in (0.0, 0.5, 2.0) for f in (0.4, 0.8)]
    df = pd.DataFrame({"align.k_ri[3]": [k for k, _ in grid],
                       "align.f_ref[2]": [f for _, f in grid],
                       "aligned": [k > 0.25 or f > 0.6 for k, f in grid],
                       "contact_breaks": [1] * len(grid), "mean_fz_align_n": [f for _, f in grid]})
    plots.sweep_figures(df, ["align.k_ri[3]", "align.f_ref[2]"], tmp_path, "t",
                        nominal={"align.k_ri[3]": 0.5, "align.f_ref[2]": 0.8})
    ax = figs[0].axes[0]
    assert ax.get_xlabel() == "$k_{xp}$ (–)" and ax.get_ylabel() == r"$f_z^\mathrm{ref}$ (N)"
    (frame,) = [p for p in ax.patches if not p.get_fill()]
    assert frame.get_xy() == pytest.approx((0.5, 0.5))  # column 1 (k_xp 0.5), row 1 (0.8 N)
    breaks = figs[0].axes[1].images[0]  # one value everywhere: a unit range around it
    assert breaks.norm.vmin == pytest.approx(0.5) and breaks.norm.vmax == pytest.approx(1.5)


@pytest.mark.parametrize("nominal", [{"align.k_ri[3]": 1.0, "align.f_ref[2]": 0.8},
                                     {"align.k_ri[3]": 0.5, "align.f_ref[2]": 0.7},
                                     {"align.k_ri[3]": 1.0, "align.f_ref[2]": 0.6}])
def test_a_nominal_between_cells_is_pointed_at_on_the_spines_not_drawn_over_numbers(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, nominal: dict[str, float]
) -> None:
    figs = captured(monkeypatch)
    grid = [(k, f) for k in (0.0, 0.5, 2.0) for f in (0.4, 0.8)]
    df = pd.DataFrame({"align.k_ri[3]": [k for k, _ in grid],
                       "align.f_ref[2]": [f for _, f in grid],
                       "aligned": [k > 0.25 for k, _ in grid],
                       "contact_breaks": [1] * len(grid), "mean_fz_align_n": [f for _, f in grid]})
    plots.sweep_figures(df, ["align.k_ri[3]", "align.f_ref[2]"], tmp_path, "t", nominal=nominal)
    for ax in figs[0].axes[:3]:
        assert not [p for p in ax.patches if not p.get_fill()]  # no frame across two cells
        xs, ys = ax.get_xlim(), ax.get_ylim()
        points = np.vstack([c.get_offsets() for c in ax.collections])
        assert len(points) == 4
        for x, y in points:  # each on a spine: never over a cell's number
            assert x in (pytest.approx(min(xs)), pytest.approx(max(xs))) or \
                y in (pytest.approx(min(ys)), pytest.approx(max(ys)))
        texts = [t.get_position() for t in ax.texts]
        assert len(texts) == len(grid)
        # k_xp 1.0 lies a third of the way from cell 1 (0.5) to cell 2 (2.0)
        bottom = [x for x, y in points if y == pytest.approx(min(ys))]
        expect = {1.0: 1 + 0.5 / 1.5, 0.5: 1.0}[nominal["align.k_ri[3]"]]
        assert bottom == [pytest.approx(expect)]
    legend = figs[0].legends[0].get_texts()[0].get_text()
    assert "between cells" in legend


def test_limits_figure_names_the_key_and_marks_limit_and_nominal(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    figs = captured(monkeypatch)
    points = [((0.0,), 0.0), ((0.5,), 1.0), ((1.0,), 1.0)]
    plots.limits_figure(points, ["align.k_ri[3]"], [(0.25,)], "m: align.k_ri[3], 1 seed(s)",
                        tmp_path / "l.png", nominal={"align.k_ri[3]": 0.5})
    ax = figs[0].axes[0]
    assert ax.get_xlabel() == "$k_{xp}$ (–)"
    assert "align.k_ri" not in ax.get_title()
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels == ["runs looked at", "limit found", "nominal"]
