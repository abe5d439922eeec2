"""The figures: one style, PNG and SVG at one resolution, a phase legend, one
unit per axis, a panel at the force scale, and never an overwritten file.

Built from a synthetic recording whose numbers are known: 1 s of APPROACH,
then ALIGN with f_z = f_ref = 0.8 N except a 20 N impact spike at contact.
"""

from __future__ import annotations

import re
import struct
from pathlib import Path

import numpy as np
import pytest

from ffexp import figures
from ffexp.contracts import Phase
from ffexp.recording.reader import Recording, TopicData

F_REF_N = 0.8
SPIKE_N = 20.0
CYCLE_NS = 5_000_000


def synthetic(path: Path, n: int = 600) -> Recording:
    t = np.arange(n, dtype=np.int64) * CYCLE_NS
    phase = np.where(np.arange(n) < 200, int(Phase.APPROACH), int(Phase.ALIGN)).astype(np.int32)
    wrench = np.zeros((n, 6))
    wrench[200:, 2] = -F_REF_N
    wrench[200:205, 2] = -SPIKE_N  # the impact
    wrench[:, 1] = 0.1 * np.sin(np.arange(n) / 20)
    wrench[:, 3] = 0.01 * np.cos(np.arange(n) / 20)
    f_ref = np.zeros((n, 6))
    f_ref[:, 2] = F_REF_N
    rec = Recording(path=path)
    rec.topics["/estimator/state"] = TopicData(
        t, {"wrench": wrench, "in_contact": (np.arange(n) >= 200).astype(np.uint8)}
    )
    rec.topics["/control/terms"] = TopicData(
        t, {"phase": phase, "total": wrench * 0.5, "f_ref": f_ref}
    )
    rec.metadata["run"] = {"protocol": "synthetic", "run_name": path.stem}
    return rec


def png_size(path: Path) -> tuple[int, int]:
    head = path.read_bytes()[:24]
    assert head[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = struct.unpack(">II", head[16:24])
    return width, height


@pytest.mark.parametrize("make", [figures.wrench_figure, figures.applied_figure])
def test_one_unit_per_axis_and_a_phase_legend(tmp_path: Path, make: object) -> None:
    rec = synthetic(tmp_path / "synthetic-base-20260101-000000.mcap")
    with figures.style():
        fig = make(rec, "synthetic")  # type: ignore[operator]
    for ax in fig.axes:
        units = set(re.findall(r"\[([^\]]+)\]", ax.get_ylabel()))
        assert len(units) == 1, ax.get_ylabel()
    labels = [t.get_text() for leg in fig.legends for t in leg.get_texts()]
    assert "APPROACH phase" in labels and "ALIGN phase" in labels


def test_the_force_scale_panel_shows_f_ref_not_the_spike(tmp_path: Path) -> None:
    rec = synthetic(tmp_path / "synthetic-base-20260101-000000.mcap")
    with figures.style():
        fig = figures.wrench_figure(rec, "synthetic")
    full, zoom = fig.axes[0], fig.axes[1]
    assert full.get_ylim()[1] >= SPIKE_N  # the full scale keeps the impact
    low, high = zoom.get_ylim()
    half = max(figures.ZOOM_MIN_N, 2 * F_REF_N)
    assert (low, high) == pytest.approx((F_REF_N - half, F_REF_N + half))
    assert high < SPIKE_N


def test_png_and_svg_at_one_resolution_never_overwritten(tmp_path: Path) -> None:
    rec = synthetic(tmp_path / "synthetic-base-20260101-000000.mcap")
    out = tmp_path / "figs"
    first = figures.write_run_figures(rec, out, "run")
    before = {p: p.read_bytes() for p in first}
    second = figures.write_run_figures(rec, out, "run")
    assert [p.name for p in first] == [
        "run_wrench.png", "run_wrench.svg", "run_applied.png", "run_applied.svg"]
    assert [p.name for p in second] == [
        "run_wrench-1.png", "run_wrench-1.svg", "run_applied-1.png", "run_applied-1.svg"]
    assert all(p.read_bytes() == b for p, b in before.items())  # the first ones untouched
    for png in (p for p in first if p.suffix == ".png"):
        svg = png.with_suffix(".svg").read_text()
        w_in = float(re.search(r'width="([\d.]+)pt"', svg).group(1)) / 72  # type: ignore[union-attr]
        assert png_size(png)[0] == pytest.approx(w_in * figures.DPI, abs=2)


def test_save_refuses_a_file_as_directory(tmp_path: Path) -> None:
    from ffexp.errors import InputError

    (tmp_path / "f").write_text("x")
    with figures.style():
        fig = figures.new_figure(2, 2)
    with pytest.raises(InputError, match="not a directory"):
        figures.save(fig, tmp_path / "f", "x")


# -- names, marks, axes --------------------------------------------------------------
METHOD_I = {"description": "Method I case I: f_ref 0.8 N, k_xp 0.5, k_yp 0.2",
            "approach": {"stiffness": [0, 0, 500.0, 0, 0, 0], "damping": [1.0] * 6,
                         "speed_mps": 0.02},
            "align": {"method": "force_ri", "f_ref": [0, 0, F_REF_N, 0, 0, 0],
                      "k_ri": [0, 0.2, 0, 0.5, 0, 0]}}
METHOD_III = {"description": "Method III: impedance control throughout",
              "align": {"method": "impedance"}}


def with_protocol(rec: Recording, proto: dict[str, object]) -> Recording:
    import json

    rec.metadata["run"].update(method=proto["align"]["method"],  # type: ignore[index]
                               protocol_json=json.dumps(proto))
    if proto["align"]["method"] == "impedance":  # type: ignore[index]
        rec.topics["/control/terms"].fields["f_ref"][:] = 0.0  # no force reference
    return rec


def legend_labels(fig: object) -> list[str]:
    return [t.get_text() for leg in fig.legends for t in leg.get_texts()]  # type: ignore[attr-defined]


def test_a_run_is_titled_with_its_method_in_the_papers_words(tmp_path: Path) -> None:
    one = with_protocol(synthetic(tmp_path / "a.mcap"), METHOD_I)
    three = with_protocol(synthetic(tmp_path / "b.mcap"), METHOD_III)
    assert figures.method_title(one) == (
        r"Method I case I: $f_z^\mathrm{ref}$ 0.8 N, $k_{xp}$ 0.5, $k_{yp}$ 0.2")
    assert figures.method_title(three) == "Method III (impedance control)"
    with figures.style():
        fig = figures.campaign_figure([("run-a", one), ("run-b", three)], "c")
    titles = [ax.get_title(loc="left") for ax in fig.axes]
    assert figures.method_title(one) in titles and "run-a" not in titles


def test_no_legend_entry_without_a_line(tmp_path: Path) -> None:
    three = with_protocol(synthetic(tmp_path / "b.mcap"), METHOD_III)
    one = with_protocol(synthetic(tmp_path / "a.mcap"), METHOD_I)
    for make in (figures.wrench_figure, figures.applied_figure):
        with figures.style():
            assert r"$f_z^\mathrm{ref}$" not in legend_labels(make(three, "b"))
            assert r"$f_z^\mathrm{ref}$" in legend_labels(make(one, "a"))


def test_a_clipped_spike_is_marked_with_its_peak(tmp_path: Path) -> None:
    rec = with_protocol(synthetic(tmp_path / "a.mcap"), METHOD_I)
    with figures.style():
        fig = figures.wrench_figure(rec, "a")
    full, zoom = fig.axes[0], fig.axes[1]
    assert [t.get_text() for t in zoom.texts] == [f"peak {SPIKE_N:.3g} N"]
    assert len(full.texts) == 0  # the full scale clips nothing
    marks = [line for line in zoom.get_lines() if line.get_marker() == "^"]
    assert len(marks) == 1 and marks[0].get_xdata()[0] == pytest.approx(200 * CYCLE_NS / 1e9)
    assert "beyond the axis (clipped): peak marked" in legend_labels(fig)


def test_the_command_is_drawn_by_phase_and_approach_explained(tmp_path: Path) -> None:
    rec = with_protocol(synthetic(tmp_path / "a.mcap"), METHOD_I)
    with figures.style():
        fig = figures.applied_figure(rec, "a")
    labels = legend_labels(fig)
    assert "commanded in APPROACH (approach law)" in labels
    assert "commanded in ALIGN (the method)" in labels
    note = fig.legends[0].get_title().get_text().replace("\n", " ")
    assert "$K_z$ 500 N/m" in note and "0.02 m/s" in note
    panel_a = fig.axes[0]
    approach = next(ln for ln in panel_a.get_lines() if "APPROACH" in str(ln.get_label()))
    y = np.asarray(approach.get_ydata(), float)
    assert np.isfinite(y[:200]).all() and np.isnan(y[200:]).all()


def test_each_run_has_its_own_time_axis(tmp_path: Path) -> None:
    short = with_protocol(synthetic(tmp_path / "a.mcap", n=300), METHOD_I)
    long = with_protocol(synthetic(tmp_path / "b.mcap", n=1200), METHOD_I)
    with figures.style():
        fig = figures.campaign_figure([("a", short), ("b", long)], "c")
    ends = sorted({round(ax.get_xlim()[1], 3) for ax in fig.axes})
    assert ends == [round(299 * CYCLE_NS / 1e9, 3), round(1199 * CYCLE_NS / 1e9, 3)]


def test_twin_axes_put_their_zeros_at_one_height(tmp_path: Path) -> None:
    rec = with_protocol(synthetic(tmp_path / "a.mcap"), METHOD_I)
    rec.topics["/estimator/state"].fields["wrench"][:, 3] += 0.05  # torque mostly > 0
    with figures.style():
        fig = figures.campaign_figure([("a", rec)], "c")
    left, twin = fig.axes[1], fig.axes[2]

    def zero_at(ax: object) -> float:
        lo, hi = ax.get_ylim()  # type: ignore[attr-defined]
        return -lo / (hi - lo)

    assert zero_at(left) == pytest.approx(zero_at(twin))
    w = rec.topics["/estimator/state"]["wrench"]
    assert twin.get_ylim()[1] >= w[:, 3].max() and left.get_ylim()[0] <= w[:, 1].min()


@pytest.mark.parametrize(("lims", "twin_lims"), [((-1, 3), (-0.1, 0.1)), ((0, 2), (-5, -1)),
                                                  ((-3, -1), (2, 4))])
def test_align_zeros_keeps_both_ranges(lims: tuple[float, float],
                                       twin_lims: tuple[float, float]) -> None:
    with figures.style():
        fig = figures.new_figure(3, 2)
    ax = fig.subplots()
    twin = ax.twinx()
    ax.set_ylim(*lims)
    twin.set_ylim(*twin_lims)
    figures.align_zeros(ax, twin)
    for a, (lo, hi) in ((ax, lims), (twin, twin_lims)):
        new_lo, new_hi = a.get_ylim()
        assert new_lo <= min(lo, 0) + 1e-12 and new_hi >= max(hi, 0) - 1e-12
    fracs = [-a.get_ylim()[0] / (a.get_ylim()[1] - a.get_ylim()[0]) for a in (ax, twin)]
    assert fracs[0] == pytest.approx(fracs[1])


def test_keys_by_their_paper_names_with_units() -> None:
    assert figures.key_label("align.k_ri[3]") == "$k_{xp}$ (–)"
    assert figures.key_label("align.k_ri[1]") == "$k_{yp}$ (–)"
    assert figures.key_label("align.f_ref[2]") == r"$f_z^\mathrm{ref}$ (N)"
    assert figures.key_label("run.timeout_s") == "run.timeout (s)"  # by its name's unit
    assert figures.key_label("scene.target.funnel.panels") == "scene.target.funnel.panels"


def test_every_line_the_force_scale_cuts_is_marked(tmp_path: Path) -> None:
    rec = with_protocol(synthetic(tmp_path / "a.mcap"), METHOD_I)
    command = rec.topics["/control/terms"].fields["total"]
    command[200:, 2] = F_REF_N
    command[300:302, 2] = -10.0  # a two-cycle kick of the command
    with figures.style():
        fig = figures.applied_figure(rec, "a")
    ax = fig.axes[0]
    lo, hi = ax.get_ylim()
    marks = [ln for ln in ax.get_lines() if ln.get_marker() in ("^", "v")]
    marked_x = np.concatenate([np.asarray(m.get_xdata(), float) for m in marks])
    cut = 0
    for line in ax.get_lines():
        if line in marks:
            continue
        t = np.asarray(line.get_xdata(), float)
        y = np.asarray(line.get_ydata(), float)
        beyond = np.isfinite(y) & ((y > hi) | (y < lo))
        if beyond.any():
            cut += 1
            assert np.min(np.abs(marked_x - t[beyond][np.argmax(np.abs(y[beyond]))])) < 1e-9
    assert cut == 2  # the contact's spike (+20 N) and the command's kick (-10 N)
    assert sorted(t.get_text() for t in ax.texts) == ["peak -10 N", "peak 20 N"]
