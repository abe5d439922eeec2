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
