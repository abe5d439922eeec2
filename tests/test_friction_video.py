"""Video to mu: synthetic videos with a known friction, through the real decoder.

Videos are rendered with a seeded generator and are kept small: 640x360 at
half the scale of the default camera (same field of view), except when the
slide lasts under 0.2 s (a handful of frames), where the resolution decides
the precision and the default 1280x720 is used. The scale is not a round
number so that no speed is an integer number of pixels per frame.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from ffexp.errors import InputError
from ffexp.friction import Scale, SynthConfig, estimate_video, write_video
from ffexp.friction.fit import G_MPS2
from ffexp.friction.track import track_video

SEED = 2026
REST_S = 0.3
SMALL = {"width_px": 640, "height_px": 360, "px_per_m": 565.0}
FULL = {"width_px": 1280, "height_px": 720, "px_per_m": 1130.0}


def _duration(mu: float, v0: float) -> float:
    """Rest, then the slide and 0.3 s at rest, capped at 0.8 s of motion."""
    slide = v0 / (mu * G_MPS2) if mu > 0 else math.inf
    return REST_S + min(slide + 0.3, 0.8)


def _render(tmp: Path, name: str, **kw: object) -> tuple[Path, SynthConfig]:
    cfg = SynthConfig(rest_s=REST_S, **kw)  # type: ignore[arg-type]
    out = tmp / f"{name}.avi"
    write_video(cfg, out, np.random.default_rng(SEED))
    return out, cfg


@pytest.mark.parametrize("v0", [0.05, 0.2])
@pytest.mark.parametrize("mu", [0.005, 0.01, 0.02, 0.05])
def test_estimate_is_accurate_and_its_interval_covers_the_truth(
    tmp_path: Path, mu: float, v0: float
) -> None:
    duration = _duration(mu, v0)
    geometry = FULL if v0 / (mu * G_MPS2) < 0.2 else SMALL
    video, cfg = _render(tmp_path, "v", mu=mu, v0_mps=v0, duration_s=duration, **geometry)
    result = estimate_video(video, Scale(px_per_m=cfg.px_per_m))
    d = result.to_dict()
    assert abs(d["mu"] - mu) <= max(0.1 * mu, 0.0005)
    assert d["mu_low"] <= mu <= d["mu_high"]
    assert d["frames_used"] >= 4
    # the window lies strictly inside the free slide
    t_imp = REST_S  # impulse in [REST_S, REST_S + 1 frame)
    assert d["window_start_s"] > t_imp
    if mu * G_MPS2 * (duration - REST_S) > v0:
        assert d["end_reason"] == "stopped"
        assert d["window_end_s"] < REST_S + 1 / cfg.fps + v0 / (mu * G_MPS2)


def test_tracking_error_is_sub_pixel(tmp_path: Path) -> None:
    cfg = SynthConfig(mu=0.02, v0_mps=0.2, duration_s=0.8, rest_s=REST_S, **SMALL)
    video = tmp_path / "t.avi"
    truth = write_video(cfg, video, np.random.default_rng(SEED))
    track = track_video(video)
    centre = np.asarray(truth.centre_px)[: track.t_s.size]
    err = track.centre_px[track.valid] - centre[track.valid]
    err -= err.mean(axis=0)  # a constant offset does not matter
    assert track.valid.sum() >= 0.8 * cfg.n_frames
    assert float(np.max(np.abs(err))) < 0.05
    assert float(np.std(err)) < 0.02


def test_zero_friction_reports_a_bound(tmp_path: Path) -> None:
    video, cfg = _render(tmp_path, "z", mu=0.0, v0_mps=0.1, duration_s=1.0, **SMALL)
    d = estimate_video(video, Scale(px_per_m=cfg.px_per_m)).to_dict()
    assert not d["significant"]
    assert d["mu_upper_bound"] >= d["mu_detect_limit"] > 0
    tq_sigma_formula = (
        d["mu_detect_limit"] * G_MPS2
    )  # t_q sqrt(720/N) sigma_x / T^2, from the reported numbers:
    sigma_x = d["sigma_x_m"]  # residual noise (pooled with the track's, inflated)
    assert sigma_x == pytest.approx(
        d["residual_std_m"] * math.sqrt(d["variance_inflation"]), rel=0.3
    )
    closed_form = math.sqrt(720.0 / d["frames_used"]) * sigma_x / d["window_s"] ** 2
    assert d["sigma_a_formula_mps2"] == pytest.approx(closed_form)
    assert tq_sigma_formula == pytest.approx(1.96 * closed_form, rel=0.05)
    # the fit's own standard error agrees with the closed form
    assert d["mu_std"] * G_MPS2 == pytest.approx(closed_form, rel=0.25)
    assert d["mu_upper_bound"] < 3.5 * d["mu_detect_limit"]


def test_diagonal_motion_with_homography_and_object_size(tmp_path: Path) -> None:
    mu, v0 = 0.02, 0.15
    video, cfg = _render(
        tmp_path, "d", mu=mu, v0_mps=v0, duration_s=1.0, direction_deg=25.0, **SMALL
    )
    # table frame: metres, rotated and shifted against the image
    ppm = cfg.px_per_m
    img = np.array([[50.0, 40.0], [600.0, 40.0], [600.0, 330.0], [50.0, 330.0]])
    rot = np.array([[0.0, -1.0], [1.0, 0.0]])
    table = (img / ppm) @ rot.T + np.array([2.0, -1.0])
    points = tmp_path / "table.json"
    points.write_text(json.dumps({"image_px": img.tolist(), "table_m": table.tolist()}))
    by_h = estimate_video(video, Scale(table_points=points)).to_dict()
    assert abs(by_h["mu"] - mu) <= 0.1 * mu
    assert by_h["mu_low"] <= mu <= by_h["mu_high"]
    assert by_h["scale_source"] == "homography"
    by_size = estimate_video(video, Scale(object_size_m=cfg.block_m)).to_dict()
    # the size is measured to about a pixel: about 1 % of scale
    assert by_size["px_per_m"] == pytest.approx(ppm, rel=0.015)
    assert abs(by_size["mu"] - mu) <= 0.1 * mu


def test_marker_tracking(tmp_path: Path) -> None:
    mu, v0 = 0.01, 0.2
    video, cfg = _render(
        tmp_path, "m", mu=mu, v0_mps=v0, duration_s=1.0, marker_dict="DICT_4X4_50", **SMALL
    )
    result = estimate_video(video, Scale(px_per_m=cfg.px_per_m), marker_dict="DICT_4X4_50")
    d = result.to_dict()
    assert d["method"] == "marker"
    assert abs(d["mu"] - mu) <= 0.1 * mu
    assert d["mu_low"] <= mu <= d["mu_high"]
    marker_side_px = cfg.block_px * cfg.marker_frac
    assert result.track.size_px == pytest.approx(marker_side_px, rel=0.02)


def test_target_leaving_the_frame_ends_the_window(tmp_path: Path) -> None:
    mu, v0 = 0.01, 0.4
    video, cfg = _render(
        tmp_path, "l", mu=mu, v0_mps=v0, duration_s=1.2, start_px=(400.0, 180.0), **SMALL
    )
    d = estimate_video(video, Scale(px_per_m=cfg.px_per_m)).to_dict()
    assert d["end_reason"] == "left_frame"
    assert d["frames_used"] < cfg.n_frames - REST_S * cfg.fps
    assert abs(d["mu"] - mu) <= 0.1 * mu


def test_user_window(tmp_path: Path) -> None:
    video, cfg = _render(tmp_path, "w", mu=0.02, v0_mps=0.2, duration_s=1.1, **SMALL)
    d = estimate_video(video, Scale(px_per_m=cfg.px_per_m), start_s=0.6, end_s=1.0).to_dict()
    assert d["end_reason"] == "user"
    assert d["window_start_s"] == pytest.approx(0.6)
    assert d["window_end_s"] == pytest.approx(1.0)
    assert d["frames_used"] == 21
    assert abs(d["mu"] - 0.02) <= 0.002


def test_unreadable_file(tmp_path: Path) -> None:
    bad = tmp_path / "bad.avi"
    bad.write_bytes(b"this is not a video\n" * 100)
    with pytest.raises(InputError, match=r"bad\.avi"):
        estimate_video(bad, Scale(px_per_m=1000.0))
    with pytest.raises(InputError, match="no such file"):
        estimate_video(tmp_path / "missing.avi", Scale(px_per_m=1000.0))


def test_no_moving_object(tmp_path: Path) -> None:
    still = tmp_path / "still.avi"
    writer = cv2.VideoWriter(
        str(still), cv2.VideoWriter.fourcc(*"FFV1"), 50.0, (320, 180), isColor=False
    )
    rng = np.random.default_rng(0)
    base = np.full((180, 320), 150.0)
    base[60:120, 100:160] = 60.0
    for _ in range(40):
        writer.write(np.clip(base + rng.normal(0, 2, base.shape), 0, 255).astype(np.uint8))
    writer.release()
    with pytest.raises(InputError, match=r"still\.avi: no moving object"):
        estimate_video(still, Scale(px_per_m=500.0))


def test_object_leaving_at_once(tmp_path: Path) -> None:
    # 2 m/s from near the right edge: gone after three frames
    video, cfg = _render(
        tmp_path, "gone", mu=0.01, v0_mps=2.0, duration_s=0.8, start_px=(540.0, 180.0), **SMALL
    )
    with pytest.raises(InputError, match=r"gone\.avi: .*leaves the frame"):
        estimate_video(video, Scale(px_per_m=cfg.px_per_m))


def test_scale_must_be_given_once() -> None:
    with pytest.raises(InputError, match="exactly one scale"):
        Scale()
    with pytest.raises(InputError, match="exactly one scale"):
        Scale(px_per_m=1000.0, object_size_m=0.2)
    with pytest.raises(InputError, match="positive"):
        Scale(px_per_m=-3.0)


def test_bad_table_points_name_the_file(tmp_path: Path) -> None:
    video, _ = _render(tmp_path, "p", mu=0.02, v0_mps=0.2, duration_s=0.8, **SMALL)
    points = tmp_path / "pts.json"
    points.write_text('{"image_px": [[0, 0]]}')
    with pytest.raises(InputError, match=r"pts\.json"):
        estimate_video(video, Scale(table_points=points))


@pytest.mark.parametrize("codec", ["ffv1", "mjpg"])
def test_blurred_video_and_lossy_codec(tmp_path: Path, codec: str) -> None:
    mu = 0.01
    cfg = SynthConfig(
        mu=mu, v0_mps=0.2, duration_s=1.1, rest_s=REST_S, blur_px=1.0, exposure_s=0.01, **SMALL
    )
    video = tmp_path / f"b_{codec}.avi"
    write_video(cfg, video, np.random.default_rng(SEED), codec=codec)  # type: ignore[arg-type]
    d = estimate_video(video, Scale(px_per_m=cfg.px_per_m)).to_dict()
    assert abs(d["mu"] - mu) <= 0.1 * mu
    if codec == "ffv1":  # MJPG's 8x8 block artefacts make errors correlated with position
        assert d["mu_low"] <= mu <= d["mu_high"]
