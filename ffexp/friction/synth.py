"""Synthetic top-view videos of a block sliding on an air bed with known friction.

The scene: a uniform table (slight vignette), a square block at rest for
``rest_s`` that receives an instantaneous impulse at a random sub-frame time,
then slides with constant deceleration ``mu g`` until it stops (or leaves the
frame, or the video ends). Rendering is sub-pixel exact in the sense that
matters for tracking: the block sprite is built by area sampling (8x
supersampling, ``INTER_AREA``) and shifted by ``warpAffine`` with bilinear
interpolation, which preserves its mass and first moment for any sub-pixel
position. Optional defocus blur, motion blur over an exposure, a slight
lighting change over time, and Gaussian sensor noise, then 8-bit rounding.

Coordinates: pixel ``(u, v)`` has its centre at integer ``(u, v)``; ``u`` to
the right, ``v`` down; metres are ``pixels / px_per_m`` from the top-left
pixel centre.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Literal

import cv2
import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, ConfigDict, Field, model_validator

from ffexp.errors import InputError
from ffexp.friction.fit import G_MPS2
from ffexp.friction.marker import aruco_dictionary

Codec = Literal["ffv1", "png", "mjpg"]

#: fourcc of each codec (all write .avi; FFV1 also .mkv).
FOURCC: dict[str, str] = {"ffv1": "FFV1", "png": "png ", "mjpg": "MJPG"}

_SUPERSAMPLE = 8
_PAD_PX = 3


class SynthConfig(BaseModel):
    """Parameters of a synthetic sliding-block video (SI units, pixels where named)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    mu: float = Field(ge=0.0, le=1.0, description="friction coefficient (deceleration / g)")
    v0_mps: float = Field(gt=0.0, le=10.0, description="speed right after the impulse (m/s)")
    duration_s: float = Field(gt=0.0, le=600.0, description="video length (s)")
    fps: float = Field(default=50.0, gt=0.0, le=1000.0)
    width_px: int = Field(default=1280, ge=64, le=8192)
    height_px: int = Field(default=720, ge=64, le=8192)
    px_per_m: float = Field(default=1000.0, gt=0.0, description="image scale (px/m)")
    block_m: float = Field(default=0.25, gt=0.0, description="side of the square block (m)")
    rest_s: float = Field(default=0.5, ge=0.0, description="time at rest before the impulse (s)")
    direction_deg: float = Field(default=0.0, description="motion direction in the image, from +u")
    start_px: tuple[float, float] | None = Field(
        default=None, description="block centre at rest (px); default centres the travel"
    )
    noise: float = Field(default=2.0, ge=0.0, description="sensor noise std (grey levels)")
    blur_px: float = Field(default=0.0, ge=0.0, description="defocus Gaussian sigma (px)")
    exposure_s: float = Field(default=0.0, ge=0.0, description="motion-blur exposure (s)")
    lighting: float = Field(
        default=0.03, ge=-0.5, le=0.5, description="relative brightening over the video"
    )
    table_grey: float = Field(default=170.0, ge=0.0, le=255.0)
    block_grey: float = Field(default=60.0, ge=0.0, le=255.0)
    marker_dict: str | None = Field(
        default=None, description="draw an ArUco/AprilTag marker from this dictionary"
    )
    marker_id: int = Field(default=0, ge=0)
    marker_frac: float = Field(default=0.6, gt=0.0, le=0.9, description="marker side / block side")
    g_mps2: float = Field(default=G_MPS2, gt=0.0)

    @model_validator(mode="after")
    def _block_fits(self) -> SynthConfig:
        side = self.block_m * self.px_per_m
        if side < 8 or side + 2 * _PAD_PX >= min(self.width_px, self.height_px):
            raise ValueError(f"the block is {side:.1f} px: it must be >= 8 px and fit the frame")
        return self

    @property
    def decel_mps2(self) -> float:
        """Deceleration while sliding (m/s²)."""
        return self.mu * self.g_mps2

    @property
    def block_px(self) -> float:
        """Block side in pixels."""
        return self.block_m * self.px_per_m

    @property
    def n_frames(self) -> int:
        """Number of frames in the video."""
        return max(1, round(self.duration_s * self.fps))


@dataclass(frozen=True)
class SynthTruth:
    """What the generator did, for checking an estimate."""

    mu: float
    decel_mps2: float
    v0_mps: float
    fps: float
    px_per_m: float
    block_m: float
    impulse_time_s: float
    #: Time the block stops (s), or None when it would stop after the video.
    stop_time_s: float | None
    #: First frame time at which the block is no longer fully inside the frame.
    leaves_frame_time_s: float | None
    direction_deg: float
    #: Block centre per frame (px), ``[[u, v], ...]``.
    centre_px: list[list[float]]
    config: dict[str, object]

    def to_json(self) -> str:
        """The truth as a JSON document."""
        return json.dumps(asdict(self), indent=1)


def displacement_m(
    t_s: npt.NDArray[np.float64], v0_mps: float, decel_mps2: float, impulse_time_s: float
) -> npt.NDArray[np.float64]:
    """Distance slid at times ``t_s``: 0 before the impulse, then ``v0 τ - a τ²/2`` until rest."""
    tau = np.clip(np.asarray(t_s, dtype=np.float64) - impulse_time_s, 0.0, None)
    if decel_mps2 > 0.0:
        tau = np.minimum(tau, v0_mps / decel_mps2)
    return v0_mps * tau - 0.5 * decel_mps2 * tau**2


class _Sprite:
    """Area-sampled block (alpha and premultiplied grey) with a transparent pad."""

    def __init__(self, cfg: SynthConfig) -> None:
        side = cfg.block_px
        n = math.ceil(side) + 2 * _PAD_PX + 1
        hi = n * _SUPERSAMPLE
        lo_px = _PAD_PX * _SUPERSAMPLE
        hi_px = round((_PAD_PX + side) * _SUPERSAMPLE)
        alpha_hi = np.zeros((hi, hi), np.float32)
        alpha_hi[lo_px:hi_px, lo_px:hi_px] = 1.0
        grey_hi = np.full((hi, hi), cfg.block_grey, np.float32)
        if cfg.marker_dict is not None:
            dictionary = aruco_dictionary(cfg.marker_dict)
            quiet = round(side * cfg.marker_frac * 1.25 * _SUPERSAMPLE)
            mside = round(side * cfg.marker_frac * _SUPERSAMPLE)
            mimg = cv2.aruco.generateImageMarker(dictionary, cfg.marker_id, mside, borderBits=1)
            centre = (lo_px + hi_px) // 2
            q0 = centre - quiet // 2
            grey_hi[q0 : q0 + quiet, q0 : q0 + quiet] = 235.0
            m0 = centre - mside // 2
            grey_hi[m0 : m0 + mside, m0 : m0 + mside] = 25.0 + mimg.astype(np.float32) * (210 / 255)
        area = cv2.INTER_AREA
        self.alpha = np.asarray(cv2.resize(alpha_hi, (n, n), interpolation=area), np.float32)
        self.premult = np.asarray(
            cv2.resize(alpha_hi * grey_hi, (n, n), interpolation=area), np.float32
        )
        #: Continuous centre of the block in sprite pixel coordinates.
        self.centre = _PAD_PX + side / 2.0 - 0.5
        self.size = n

    def place(self, centre_u: float, centre_v: float) -> tuple[int, int, float, float]:
        """Integer top-left corner and sub-pixel shift that put the centre at ``(u, v)``."""
        x = centre_u - self.centre
        y = centre_v - self.centre
        iu, iv = math.floor(x), math.floor(y)
        return iu, iv, x - iu, y - iv

    def shifted(
        self, fu: float, fv: float
    ) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]]:
        """Alpha and premultiplied grey shifted by ``(fu, fv)`` px (size + 1).

        Exact bilinear shift in numpy: ``cv2.warpAffine`` quantises sub-pixel
        positions to 1/32 px (``INTER_BITS = 5``), i.e. up to ±0.016 px.
        """
        return _shift(self.alpha, fu, fv), _shift(self.premult, fu, fv)


def _shift(img: npt.NDArray[np.float32], fu: float, fv: float) -> npt.NDArray[np.float32]:
    """``out[y, x] = img(y - fv, x - fu)`` by bilinear interpolation, zero outside."""
    p = np.zeros((img.shape[0] + 2, img.shape[1] + 2), np.float64)
    p[1:-1, 1:-1] = img
    # out has the size of img + 1: rows/cols 0..n map to p rows/cols 1..n+1 (and -1 shifted)
    cur = p[1:, 1:]
    left = p[1:, :-1]
    up = p[:-1, 1:]
    diag = p[:-1, :-1]
    out = (1 - fv) * ((1 - fu) * cur + fu * left) + fv * ((1 - fu) * up + fu * diag)
    return np.asarray(out, np.float32)


def _illumination(cfg: SynthConfig) -> npt.NDArray[np.float32]:
    """Relative illumination with a slight vignette (multiplies the whole scene)."""
    v, u = np.mgrid[0 : cfg.height_px, 0 : cfg.width_px].astype(np.float32)
    r2 = ((u - cfg.width_px / 2) / cfg.width_px) ** 2 + (
        (v - cfg.height_px / 2) / cfg.width_px
    ) ** 2
    return np.asarray(1.0 - 0.15 * r2, np.float32)


def _start_px(
    cfg: SynthConfig, direction: npt.NDArray[np.float64], travel_px: float
) -> npt.NDArray[np.float64]:
    if cfg.start_px is not None:
        return np.array(cfg.start_px, np.float64)
    centre = np.array([(cfg.width_px - 1) / 2.0, (cfg.height_px - 1) / 2.0])
    half_span = np.array([cfg.width_px, cfg.height_px]) / 2.0 - cfg.block_px / 2.0 - 8.0
    along = float(np.min(half_span / np.maximum(np.abs(direction), 1e-9)))
    back = min(travel_px / 2.0, along)
    return centre - back * direction


def frames(
    cfg: SynthConfig, rng: np.random.Generator
) -> tuple[SynthTruth, Iterator[npt.NDArray[np.uint8]]]:
    """The truth and an iterator over the grey ``uint8`` frames of the video.

    Args:
        cfg: scene and camera parameters.
        rng: seeded generator for the impulse phase and the sensor noise.
    """
    dt = 1.0 / cfg.fps
    t_frames = np.arange(cfg.n_frames, dtype=np.float64) * dt
    t_imp = cfg.rest_s + float(rng.uniform(0.0, dt))
    a = cfg.decel_mps2
    stop = t_imp + cfg.v0_mps / a if a > 0.0 else math.inf
    ang = math.radians(cfg.direction_deg)
    direction = np.array([math.cos(ang), math.sin(ang)])
    t_end = min(stop, t_frames[-1])
    travel_px = float(displacement_m(np.array([t_end]), cfg.v0_mps, a, t_imp)[0]) * cfg.px_per_m
    start = _start_px(cfg, direction, travel_px)
    s_px = displacement_m(t_frames, cfg.v0_mps, a, t_imp) * cfg.px_per_m
    centres = start[None, :] + s_px[:, None] * direction[None, :]
    half = cfg.block_px / 2.0
    inside = (
        (centres[:, 0] - half >= -0.5)
        & (centres[:, 0] + half <= cfg.width_px - 0.5)
        & (centres[:, 1] - half >= -0.5)
        & (centres[:, 1] + half <= cfg.height_px - 0.5)
    )
    if not bool(inside[0]):
        raise ValueError("start_px: the block does not fit in the frame at its start position")
    leaves = None if bool(inside.all()) else float(t_frames[int(np.argmin(inside))])
    truth = SynthTruth(
        mu=cfg.mu,
        decel_mps2=a,
        v0_mps=cfg.v0_mps,
        fps=cfg.fps,
        px_per_m=cfg.px_per_m,
        block_m=cfg.block_m,
        impulse_time_s=t_imp,
        stop_time_s=stop if stop <= t_frames[-1] else None,
        leaves_frame_time_s=leaves,
        direction_deg=cfg.direction_deg,
        centre_px=[[float(c[0]), float(c[1])] for c in centres],
        config=cfg.model_dump(mode="json"),
    )
    return truth, _render(cfg, rng, t_frames, centres, t_imp, start, direction)


def _render(
    cfg: SynthConfig,
    rng: np.random.Generator,
    t_frames: npt.NDArray[np.float64],
    centres: npt.NDArray[np.float64],
    t_imp: float,
    start: npt.NDArray[np.float64],
    direction: npt.NDArray[np.float64],
) -> Iterator[npt.NDArray[np.uint8]]:
    sprite = _Sprite(cfg)
    illum = _illumination(cfg)
    table = np.full_like(illum, cfg.table_grey)
    h, w = cfg.height_px, cfg.width_px
    ramp = (0.5 + np.arange(w, dtype=np.float32) / w)[None, :]
    n_sub = 8 if cfg.exposure_s > 0.0 else 1
    blur_pad = math.ceil(3.0 * cfg.blur_px) + 1 if cfg.blur_px > 0.0 else 0
    duration = max(float(t_frames[-1]), 1e-9)
    for k, t in enumerate(t_frames):
        frame = table.copy()
        if n_sub == 1:
            subs = centres[k : k + 1]
        else:
            ts = t + cfg.exposure_s * (np.arange(n_sub) + 0.5 - n_sub / 2.0) / n_sub
            s = displacement_m(ts, cfg.v0_mps, cfg.decel_mps2, t_imp) * cfg.px_per_m
            subs = start[None, :] + s[:, None] * direction[None, :]
        alpha_acc: npt.NDArray[np.float32] | None = None
        prem_acc: npt.NDArray[np.float32] | None = None
        iu0 = iv0 = 0
        for c in subs:
            iu, iv, fu, fv = sprite.place(float(c[0]), float(c[1]))
            a, p = sprite.shifted(fu, fv)
            if alpha_acc is None or prem_acc is None:
                iu0, iv0 = iu, iv
                big = (sprite.size + 1 + 2 * n_sub * 4, sprite.size + 1 + 2 * n_sub * 4)
                alpha_acc = np.zeros(big, np.float32)
                prem_acc = np.zeros(big, np.float32)
            du, dv = iu - iu0 + n_sub * 4, iv - iv0 + n_sub * 4
            if not (
                0 <= du and 0 <= dv and du + a.shape[1] <= big[1] and dv + a.shape[0] <= big[0]
            ):
                raise ValueError(
                    "exposure_s: motion blur spans more than the sprite margin: shorten it"
                )
            alpha_acc[dv : dv + a.shape[0], du : du + a.shape[1]] += a / n_sub
            prem_acc[dv : dv + a.shape[0], du : du + a.shape[1]] += p / n_sub
        assert alpha_acc is not None and prem_acc is not None
        off = n_sub * 4
        _composite(frame, alpha_acc, prem_acc, iu0 - off, iv0 - off)
        if blur_pad:
            u0 = max(iu0 - off - blur_pad, 0)
            v0 = max(iv0 - off - blur_pad, 0)
            u1 = min(iu0 - off + alpha_acc.shape[1] + blur_pad, w)
            v1 = min(iv0 - off + alpha_acc.shape[0] + blur_pad, h)
            roi = frame[v0:v1, u0:u1]
            roi[:] = cv2.GaussianBlur(roi, (0, 0), cfg.blur_px, borderType=cv2.BORDER_REPLICATE)
        frame *= illum * (1.0 + np.float32(cfg.lighting * float(t) / duration) * ramp)
        if cfg.noise > 0.0:
            frame += rng.standard_normal((h, w), dtype=np.float32) * np.float32(cfg.noise)
        np.clip(frame, 0.0, 255.0, out=frame)
        yield np.rint(frame).astype(np.uint8)


def _composite(
    frame: npt.NDArray[np.float32],
    alpha: npt.NDArray[np.float32],
    premult: npt.NDArray[np.float32],
    u0: int,
    v0: int,
) -> None:
    """``frame = frame (1 - alpha) + premult`` on the overlap, in place."""
    h, w = frame.shape
    fu0, fv0 = max(u0, 0), max(v0, 0)
    fu1, fv1 = min(u0 + alpha.shape[1], w), min(v0 + alpha.shape[0], h)
    if fu1 <= fu0 or fv1 <= fv0:
        return
    a = alpha[fv0 - v0 : fv1 - v0, fu0 - u0 : fu1 - u0]
    p = premult[fv0 - v0 : fv1 - v0, fu0 - u0 : fu1 - u0]
    roi = frame[fv0:fv1, fu0:fu1]
    roi[:] = roi * (1.0 - a) + p


def write_video(
    cfg: SynthConfig,
    out: Path,
    rng: np.random.Generator,
    *,
    codec: Codec = "ffv1",
    truth_path: Path | None = None,
) -> SynthTruth:
    """Render the video to ``out`` (grey frames) and optionally its truth as JSON.

    Args:
        cfg: scene and camera parameters.
        out: output video (``.avi``; ``.mkv`` also works with FFV1).
        rng: seeded generator.
        codec: ``ffv1`` or ``png`` (lossless) or ``mjpg`` (lossy).
        truth_path: where to write the truth JSON, if anywhere.

    Raises:
        InputError: the writer cannot be opened for ``out``.
    """
    truth, it = frames(cfg, rng)
    fourcc = cv2.VideoWriter.fourcc(*FOURCC[codec])
    writer = cv2.VideoWriter(
        str(out), fourcc, cfg.fps, (cfg.width_px, cfg.height_px), isColor=False
    )
    if not writer.isOpened():
        raise InputError(f"{out}: cannot open a {codec} video writer (try a .avi name)")
    try:
        for frame in it:
            writer.write(frame)
    finally:
        writer.release()
    if truth_path is not None:
        truth_path.write_text(truth.to_json() + "\n", encoding="utf-8")
    return truth
