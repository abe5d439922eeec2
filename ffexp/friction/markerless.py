"""Markerless tracking of the target against a still background.

A background model from the first still frames (per-pixel mean), motion onset
from the coarse difference to it, the target = the connected region of the
background model that differs from the table and overlaps the first moving
blob. Its footprint is filled in the background with a smooth surface fitted
to the table around it (:func:`fill_smooth`), which gives the empty table;
every frame's target position is then the centroid (``cv2.moments``) of the
relative contrast ``frame / background - 1`` in a window that follows the
target, with the illumination re-levelled from the window border (lighting
changes). Area sampling and linear interpolation preserve the first moment,
so this centroid has no pixel-locking bias.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

from drivers.base.types import F64
from ffexp.errors import InputError
from ffexp.friction.video import (
    Frame,
    Grey8,
    GreyF,
    ProgressFn,
    TrackEnd,
    to_grey,
)


@dataclass
class _Target:
    """Footprint geometry and clean background of the markerless target."""

    bg: GreyF  # empty-table background, full frame
    polarity: float  # +1 target brighter than the table, -1 darker
    box: tuple[int, int, int, int]  # u0, v0, u1, v1 (exclusive) of the window at rest
    centre0: F64  # centroid at rest (px)
    mass0: float  # sum of weights at rest
    size_px: float


def fill_smooth(patch: GreyF, hole: npt.NDArray[np.bool_]) -> GreyF:
    """Fill ``hole`` with a quadratic surface fitted (robustly) to the rest of ``patch``.

    The empty table under the target at rest is not observed; a smooth table
    under smooth illumination is a low-order surface, which this recovers
    without the edge-propagation artefacts of ``cv2.inpaint``.
    """
    h, w = patch.shape
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    x = 2.0 * xs / max(w - 1, 1) - 1.0
    y = 2.0 * ys / max(h - 1, 1) - 1.0
    basis = np.stack([np.ones_like(x), x, y, x * x, x * y, y * y], axis=-1)
    keep = ~hole
    values = patch.astype(np.float64)
    coef = np.zeros(6)
    for _ in range(3):
        coef = np.linalg.lstsq(basis[keep], values[keep], rcond=None)[0]
        resid = values - basis @ coef
        scale = 1.4826 * float(np.median(np.abs(resid[~hole]))) + 1e-6
        keep = ~hole & (np.abs(resid) < 4.0 * scale)
    out = patch.copy()
    out[hole] = (basis[hole] @ coef).astype(np.float32)
    return out


class BackgroundTracker:
    """Markerless tracker (see the module docstring)."""

    def __init__(
        self,
        size: tuple[int, int],
        *,
        max_bg_frames: int = 20,
        min_bg_frames: int = 3,
        coarse: int = 4,
        margin_px: int = 6,
    ) -> None:
        self.w, self.h = size
        self.max_bg = max_bg_frames
        self.min_bg = min_bg_frames
        self.coarse = coarse
        self.margin = margin_px
        self.small_size = (max(self.w // coarse, 1), max(self.h // coarse, 1))

    def _small(self, grey: Grey8) -> GreyF:
        return cv2.resize(grey, self.small_size, interpolation=cv2.INTER_AREA).astype(np.float32)

    def run(
        self,
        frames: Iterator[Frame],
        path: Path,
        progress: ProgressFn | None,
        total: int,
        still_stop_s: float,
        fps: float,
    ) -> tuple[list[F64 | None], TrackEnd, float, int, float]:
        """Track; returns per-frame centres (None = invalid), end, size, frames read, noise."""
        # 1. still frames for the background model
        bg_frames: list[Grey8] = []
        buffer: deque[Grey8] = deque(maxlen=self.max_bg + 10)
        first_small: GreyF | None = None
        n_read = 0
        pending: Grey8 | None = None
        for raw in frames:
            n_read += 1
            if progress is not None:
                progress(n_read, total)
            grey = to_grey(raw)
            small = self._small(grey)
            if first_small is None:
                first_small = small
            elif float(np.max(np.abs(small - first_small))) > 12.0:
                pending = grey
                break
            bg_frames.append(grey)
            if len(bg_frames) >= self.max_bg:
                break
        if len(bg_frames) < self.min_bg:
            raise InputError(
                f"{path}: the scene is not still in the first frames "
                f"(need {self.min_bg} still frames for the background model)"
            )
        stack = np.stack(bg_frames).astype(np.float32)
        # mean, not median: the median of dithered 8-bit samples is quantised to
        # 0.5 grey levels, a banded pattern that biases the centroid smoothly
        bg0 = stack.mean(axis=0, dtype=np.float32)
        k = len(bg_frames)
        sub = np.abs(stack[:, ::4, ::4] - bg0[::4, ::4])
        noise = float(1.4826 * np.median(sub)) * math.sqrt(k / max(k - 1, 1))
        noise = max(noise, 0.5)
        del stack
        small_bg = cv2.resize(bg0, self.small_size, interpolation=cv2.INTER_AREA)
        buffer.extend(bg_frames)
        # 2. motion onset
        thr_small = max(6.0 * noise / self.coarse, 4.0)
        changed: npt.NDArray[np.bool_] | None = None

        def check(grey: Grey8) -> npt.NDArray[np.bool_] | None:
            small = self._small(grey)
            gain = float(np.median(small)) / max(float(np.median(small_bg)), 1e-6)
            mask = np.abs(small - gain * small_bg) > thr_small
            if int(np.count_nonzero(mask)) >= 4:
                return np.asarray(mask, np.bool_)
            return None

        stream = iter(frames)
        if pending is not None:
            buffer.append(pending)
            changed = check(pending)
        while changed is None:
            raw_next = next(stream, None)
            if raw_next is None:
                raise InputError(
                    f"{path}: no moving object (nothing changes against the first frames)"
                )
            n_read += 1
            if progress is not None:
                progress(n_read, total)
            nxt = to_grey(raw_next)
            buffer.append(nxt)
            changed = check(nxt)
        # 3. segment the target in the background model
        target = self._segment(bg0, changed, noise, path)
        first_index = n_read - len(buffer)
        centres: list[F64 | None] = [None] * first_index
        state = _Follow(target, self.margin, self.w, self.h)
        end: TrackEnd = "end_of_video"
        still_frames = 0
        moved = False
        still_limit = max(round(still_stop_s * fps), 5) if still_stop_s > 0 else 0

        def step(frame: Frame) -> bool:
            nonlocal end, still_frames, moved
            c = state.measure(frame)
            centres.append(c)
            if c is None:
                end = state.why
                return False
            if state.displacement_px > 3.0:
                moved = True
            if moved and still_limit:
                still_frames = still_frames + 1 if state.last_step_px < 0.05 else 0
                if still_frames >= still_limit:
                    end = "still"
                    return False
            return True

        going = True
        for grey in buffer:
            if not step(grey):
                going = False
                break
        buffer.clear()
        if going:
            for raw in stream:
                n_read += 1
                if progress is not None:
                    progress(n_read, total)
                if not step(raw):
                    break
        return centres, end, target.size_px, n_read, noise

    def _segment(
        self, bg0: GreyF, changed: npt.NDArray[np.bool_], noise: float, path: Path
    ) -> _Target:
        f = self.coarse
        ys, xs = np.nonzero(changed)
        bu0, bu1 = int(xs.min()) * f, (int(xs.max()) + 1) * f
        bv0, bv1 = int(ys.min()) * f, (int(ys.max()) + 1) * f
        change_full = cv2.resize(
            changed.astype(np.uint8), (self.w, self.h), interpolation=cv2.INTER_NEAREST
        )
        grow = max(bu1 - bu0, bv1 - bv0, 32)
        comp: npt.NDArray[np.uint8] | None = None
        for _ in range(4):
            u0, v0 = max(bu0 - grow, 0), max(bv0 - grow, 0)
            u1, v1 = min(bu1 + grow, self.w), min(bv1 + grow, self.h)
            roi = bg0[v0:v1, u0:u1]
            border = np.concatenate(
                [roi[:2].ravel(), roi[-2:].ravel(), roi[:, :2].ravel(), roi[:, -2:].ravel()]
            )
            table = float(np.median(border))
            d = roi - table
            contrast = float(np.percentile(np.abs(d), 99.5))
            thr = max(8.0 * noise, 0.5 * contrast)
            mask = (np.abs(d) > thr).astype(np.uint8)
            mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, np.ones((5, 5), np.uint8))
            n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
            if n <= 1:
                break
            overlap = np.bincount(labels[change_full[v0:v1, u0:u1] > 0].ravel(), minlength=n)
            overlap[0] = 0
            best = (
                int(np.argmax(overlap))
                if overlap.max() > 0
                else 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
            )
            x, y, w, h = (int(stats[best, i]) for i in range(4))
            touches_roi = x == 0 or y == 0 or x + w == u1 - u0 or y + h == v1 - v0
            touches_frame = (
                x + u0 == 0 or y + v0 == 0 or x + u0 + w == self.w or y + v0 + h == self.h
            )
            if touches_frame:
                raise InputError(
                    f"{path}: the moving object touches the image border at rest "
                    "(markerless tracking needs it fully in view; try --marker)"
                )
            if not touches_roi:
                comp = (labels == best).astype(np.uint8)
                break
            grow *= 2
        if comp is None:
            raise InputError(
                f"{path}: no target found at rest where the motion starts "
                "(markerless tracking needs a target that differs from the table and is still "
                "at the start; try --marker)"
            )
        contours, _ = cv2.findContours(comp, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        filled = np.zeros_like(comp)
        cv2.drawContours(filled, contours, -1, 1, thickness=cv2.FILLED)
        area = int(filled.sum())
        if area < 30:
            raise InputError(f"{path}: the moving object is too small ({area} px) to track")
        rect = cv2.minAreaRect(max(contours, key=cv2.contourArea))
        # minAreaRect of pixel centres: add one pixel for the pixel extent
        size_px = float(max(rect[1])) + 1.0
        hole = cv2.dilate(filled, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (9, 9)))
        full_hole = np.zeros((self.h, self.w), np.uint8)
        full_hole[v0:v1, u0:u1] = hole
        hv, hu = np.nonzero(full_hole)
        pu0, pu1 = max(int(hu.min()) - 24, 0), min(int(hu.max()) + 25, self.w)
        pv0, pv1 = max(int(hv.min()) - 24, 0), min(int(hv.max()) + 25, self.h)
        bg = bg0.copy()
        bg[pv0:pv1, pu0:pu1] = fill_smooth(bg0[pv0:pv1, pu0:pu1], full_hole[pv0:pv1, pu0:pu1] > 0)
        np.maximum(bg, 1.0, out=bg)
        polarity = 1.0 if float(np.sum(d[filled > 0])) > 0 else -1.0
        ys2, xs2 = np.nonzero(filled)
        m = self.margin
        box = (
            int(xs2.min()) + u0 - m,
            int(ys2.min()) + v0 - m,
            int(xs2.max()) + u0 + 1 + m,
            int(ys2.max()) + v0 + 1 + m,
        )
        if box[0] < 0 or box[1] < 0 or box[2] > self.w or box[3] > self.h:
            raise InputError(f"{path}: the target is too close to the image border at rest")
        win = bg0[box[1] : box[3], box[0] : box[2]]
        wts = polarity * (win / bg[box[1] : box[3], box[0] : box[2]] - 1.0)
        mom = cv2.moments(wts)
        if mom["m00"] <= 0:
            raise InputError(f"{path}: the target has no contrast against the table")
        centre0 = np.array([box[0] + mom["m10"] / mom["m00"], box[1] + mom["m01"] / mom["m00"]])
        return _Target(
            bg=bg,
            polarity=polarity,
            box=box,
            centre0=centre0,
            mass0=float(mom["m00"]),
            size_px=size_px,
        )


class _Follow:
    """Window-following centroid measurement of the markerless target.

    The centroid window is the target's footprint box plus a margin; an
    annulus ``ANNULUS_PX`` wide around it (table only) gives, in every frame,
    the illumination relative to the background as a plane (level and
    gradient), fitted by least squares: wide enough that its noise adds
    little, and per frame, so that the errors stay uncorrelated in time.
    """

    ANNULUS_PX = 12

    def __init__(self, target: _Target, margin: int, w: int, h: int) -> None:
        self.t = target
        self.w, self.h = w, h
        self.inv_bg = np.asarray(1.0 / target.bg, np.float32)
        a = self.ANNULUS_PX
        bw, bh = target.box[2] - target.box[0], target.box[3] - target.box[1]
        ow, oh = bw + 2 * a, bh + 2 * a
        ys, xs = np.mgrid[0:oh, 0:ow].astype(np.float64)
        gx = (xs - ow / 2) / ow
        gy = (ys - oh / 2) / oh
        ring = np.ones((oh, ow), bool)
        ring[a:-a, a:-a] = False
        self.ring_mask = ring
        design = np.stack([np.ones(int(ring.sum())), gx[ring], gy[ring]], axis=1)
        self.ring_pinv = np.linalg.pinv(design)
        self.grid_x = gx[a:-a, a:-a].astype(np.float32)
        self.grid_y = gy[a:-a, a:-a].astype(np.float32)
        self.last: F64 = target.centre0.copy()
        self.velocity: F64 = np.zeros(2)
        self.why: TrackEnd = "end_of_video"
        self.displacement_px = 0.0
        self.last_step_px = 0.0
        self._gain = np.empty((bh, bw), np.float32)

    def _at(self, frame: Frame, centre: F64) -> F64 | None:
        t = self.t
        a = self.ANNULUS_PX
        off = np.rint(centre - t.centre0).astype(int)
        u0, v0, u1, v1 = t.box[0] + off[0], t.box[1] + off[1], t.box[2] + off[0], t.box[3] + off[1]
        if u0 - a < 0 or v0 - a < 0 or u1 + a > self.w or v1 + a > self.h:
            self.why = "left_frame"
            return None
        outer = to_grey(frame[v0 - a : v1 + a, u0 - a : u1 + a]).astype(np.float32)
        outer *= self.inv_bg[v0 - a : v1 + a, u0 - a : u1 + a]
        # Weights: the relative contrast frame / (illumination x background) - 1,
        # proportional to the target's coverage under any illumination.
        level, gx, gy = self.ring_pinv @ outer[self.ring_mask]
        gain = self._gain
        np.multiply(self.grid_x, np.float32(gx), out=gain)
        gain += self.grid_y * np.float32(gy)
        gain += np.float32(level)
        ratio = outer[a:-a, a:-a]
        ratio /= gain
        ratio -= np.float32(1.0)
        if t.polarity < 0:
            np.negative(ratio, out=ratio)
        mom = cv2.moments(ratio)
        m00 = mom["m00"]
        if not 0.5 * t.mass0 < m00 < 2.0 * t.mass0:
            self.why = "lost"
            return None
        return np.array([u0 + mom["m10"] / m00, v0 + mom["m01"] / m00])

    def measure(self, frame: Frame) -> F64 | None:
        guess = self.last + self.velocity
        c: F64 | None = None
        for _ in range(4):
            c = self._at(frame, guess)
            if c is None:
                return None
            same = np.rint(c - self.t.centre0) == np.rint(guess - self.t.centre0)
            if bool(same.all()):
                break
            guess = c
        assert c is not None
        step = c - self.last
        self.velocity = step
        self.last_step_px = float(np.hypot(*step))
        self.last = c
        self.displacement_px = float(np.hypot(*(c - self.t.centre0)))
        return c
