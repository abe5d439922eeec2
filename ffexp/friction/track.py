"""Find and track the target in a video; convert pixels to metres.

Two trackers, both sub-pixel:

- **background** (markerless, the default): a background model from the
  first still frames (per-pixel mean), motion onset from the coarse
  difference to it, the target = the connected region of the background
  model that differs from the table and overlaps the first moving blob. Its
  footprint is filled in the background with a smooth surface fitted to the
  table around it (:func:`fill_smooth`), which gives the empty table;
  every frame's target position is then the centroid (``cv2.moments``) of
  the relative contrast ``frame / background - 1`` in a window that follows
  the target, with the illumination re-levelled from the window border
  (lighting changes). Area sampling and linear
  interpolation preserve the first moment, so this centroid has no
  pixel-locking bias.
- **marker**: an ArUco/AprilTag marker of a given dictionary, detected with
  sub-pixel corner refinement (in a window around the last detection); the
  centre is the intersection of the diagonals.

Pixel ``(u, v)`` has its centre at integer ``(u, v)`` (OpenCV convention).
"""

from __future__ import annotations

import contextlib
import math
import queue
import threading
from collections import deque
from collections.abc import Callable, Generator, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import cv2
import numpy as np
import numpy.typing as npt

from ffexp.errors import InputError

FloatArray = npt.NDArray[np.float64]
GreyF = npt.NDArray[np.float32]
Grey8 = npt.NDArray[np.uint8]
#: A decoded frame: BGR (h, w, 3) or grey (h, w).
Frame = npt.NDArray[np.uint8]

#: ``progress(frames_done, frames_total_or_0)``.
ProgressFn = Callable[[int, int], None]

TrackEnd = Literal["end_of_video", "left_frame", "lost", "still"]


@contextlib.contextmanager
def quiet_opencv() -> Iterator[None]:
    """Silence OpenCV's own logging (decoder warnings on stderr) for a while."""
    old = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    try:
        yield
    finally:
        cv2.utils.logging.setLogLevel(old)


@dataclass
class Track:
    """Per-frame target centre in pixels, with validity."""

    video: str
    fps: float
    frame_size: tuple[int, int]
    t_s: FloatArray
    centre_px: FloatArray
    valid: npt.NDArray[np.bool_]
    #: How tracking ended.
    end: TrackEnd
    method: Literal["background", "marker"]
    #: Target extent in pixels (long side of the footprint, or marker side).
    size_px: float
    frames_read: int
    #: Position noise of the background model, grey levels (0 for markers).
    noise_grey: float = 0.0
    extra: dict[str, float] = field(default_factory=dict)

    @property
    def left_frame(self) -> bool:
        """Tracking ended because the target left the frame (or was lost)."""
        return self.end in ("left_frame", "lost")


class VideoFrames:
    """Grey frames of a video read with ``cv2.VideoCapture``.

    Raises:
        InputError: the file is missing or OpenCV cannot decode it.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        if not path.is_file():
            raise InputError(f"{path}: no such file")
        with quiet_opencv():
            cap = cv2.VideoCapture(str(path))
            if not cap.isOpened():
                raise InputError(f"{path}: cannot read video (OpenCV cannot open it)")
            ok, first = cap.read()
        if not ok or first is None:
            cap.release()
            raise InputError(f"{path}: cannot read video (no decodable frame)")
        self._cap = cap
        self._first: npt.NDArray[np.uint8] | None = np.asarray(first, np.uint8)
        fps = float(cap.get(cv2.CAP_PROP_FPS))
        self.fps = fps if math.isfinite(fps) and fps > 0 else 0.0
        count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
        self.frame_count = max(count, 0)
        self.size = (int(first.shape[1]), int(first.shape[0]))

    def __iter__(self) -> Generator[Frame, None, None]:
        """Decoded frames as OpenCV returns them (BGR, or grey).

        Decoding runs in a read-ahead thread (OpenCV releases the GIL while
        decoding), so that it overlaps with tracking.
        """
        frames: queue.Queue[Frame | None] = queue.Queue(maxsize=8)
        stop = threading.Event()

        def read_ahead() -> None:
            try:
                while not stop.is_set():
                    ok, nxt = self._cap.read()
                    if not ok or nxt is None:
                        break
                    while not stop.is_set():
                        try:
                            frames.put(np.asarray(nxt, np.uint8), timeout=0.1)
                            break
                        except queue.Full:
                            continue
            finally:
                while not stop.is_set():
                    try:
                        frames.put(None, timeout=0.1)
                        break
                    except queue.Full:
                        continue

        first = self._first
        self._first = None
        if first is None:
            return
        with quiet_opencv():
            worker = threading.Thread(target=read_ahead, name="ffexp-video-read", daemon=True)
            worker.start()
            try:
                yield first
                while (frame := frames.get()) is not None:
                    yield frame
            finally:
                stop.set()
                while worker.is_alive():
                    try:
                        frames.get(timeout=0.05)
                    except queue.Empty:
                        pass
                worker.join()
                self.close()

    def close(self) -> None:
        """Release the decoder."""
        self._cap.release()


def _to_grey(frame: Frame) -> Grey8:
    if frame.ndim == 2:
        return frame
    if frame.shape[2] == 1:
        return frame[:, :, 0]
    return cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)  # type: ignore[return-value]


def diagonal_centre(corners: FloatArray) -> FloatArray:
    """Intersection of the diagonals of a quadrilateral (4, 2)."""
    p0, p1, p2, p3 = (np.asarray(c, np.float64) for c in corners)
    d1 = p2 - p0
    d2 = p3 - p1
    mat = np.array([[d1[0], -d2[0]], [d1[1], -d2[1]]])
    if abs(np.linalg.det(mat)) < 1e-12:
        return np.asarray(corners, np.float64).mean(axis=0)  # type: ignore[no-any-return]
    lam, _ = np.linalg.solve(mat, p1 - p0)
    return p0 + lam * d1  # type: ignore[no-any-return]


# --------------------------------------------------------------------------- background


@dataclass
class _Target:
    """Footprint geometry and clean background of the markerless target."""

    bg: GreyF  # empty-table background, full frame
    polarity: float  # +1 target brighter than the table, -1 darker
    box: tuple[int, int, int, int]  # u0, v0, u1, v1 (exclusive) of the window at rest
    centre0: FloatArray  # centroid at rest (px)
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


class _BackgroundTracker:
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
    ) -> tuple[list[FloatArray | None], TrackEnd, float, int, float]:
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
            grey = _to_grey(raw)
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
            nxt = _to_grey(raw_next)
            buffer.append(nxt)
            changed = check(nxt)
        # 3. segment the target in the background model
        target = self._segment(bg0, changed, noise, path)
        first_index = n_read - len(buffer)
        centres: list[FloatArray | None] = [None] * first_index
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
        self.last: FloatArray = target.centre0.copy()
        self.velocity: FloatArray = np.zeros(2)
        self.why: TrackEnd = "end_of_video"
        self.displacement_px = 0.0
        self.last_step_px = 0.0
        self._gain = np.empty((bh, bw), np.float32)

    def _at(self, frame: Frame, centre: FloatArray) -> FloatArray | None:
        t = self.t
        a = self.ANNULUS_PX
        off = np.rint(centre - t.centre0).astype(int)
        u0, v0, u1, v1 = t.box[0] + off[0], t.box[1] + off[1], t.box[2] + off[0], t.box[3] + off[1]
        if u0 - a < 0 or v0 - a < 0 or u1 + a > self.w or v1 + a > self.h:
            self.why = "left_frame"
            return None
        outer = _to_grey(frame[v0 - a : v1 + a, u0 - a : u1 + a]).astype(np.float32)
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

    def measure(self, frame: Frame) -> FloatArray | None:
        guess = self.last + self.velocity
        c: FloatArray | None = None
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


# --------------------------------------------------------------------------- markers


class _MarkerTracker:
    def __init__(
        self, dictionary: cv2.aruco.Dictionary, marker_id: int | None, size: tuple[int, int]
    ) -> None:
        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        params.cornerRefinementMinAccuracy = 0.005
        params.cornerRefinementMaxIterations = 50
        self.detector = cv2.aruco.ArucoDetector(dictionary, params)
        self.marker_id = marker_id
        self.w, self.h = size
        self.last: FloatArray | None = None
        self.side_px = 0.0
        self.sides: list[float] = []
        self.velocity: FloatArray = np.zeros(2)
        self.misses = 0

    def _detect(self, frame: Frame, u0: int, v0: int) -> FloatArray | None:
        corners, ids, _ = self.detector.detectMarkers(np.ascontiguousarray(_to_grey(frame)))
        if ids is None or len(ids) == 0:
            return None
        flat = [int(i) for i in np.asarray(ids).ravel()]
        if self.marker_id is None:
            self.marker_id = flat[0]
        if self.marker_id not in flat:
            return None
        quad = np.asarray(corners[flat.index(self.marker_id)], np.float64).reshape(4, 2)
        quad = quad + np.array([u0, v0], np.float64)
        sides = np.linalg.norm(quad - np.roll(quad, -1, axis=0), axis=1)
        self.sides.append(float(sides.mean()))
        return diagonal_centre(quad)

    def measure(self, frame: Frame) -> FloatArray | None:
        c: FloatArray | None = None
        if self.last is not None and self.sides:
            side = float(np.median(self.sides[-20:]))
            guess = self.last + self.velocity
            half = side * 0.75 + 4 * self.misses + float(np.hypot(*self.velocity)) + 8
            u0, v0 = max(int(guess[0] - half), 0), max(int(guess[1] - half), 0)
            u1, v1 = min(int(guess[0] + half) + 1, self.w), min(int(guess[1] + half) + 1, self.h)
            if u1 - u0 > 8 and v1 - v0 > 8:
                c = self._detect(frame[v0:v1, u0:u1], u0, v0)
        if c is None:
            c = self._detect(frame, 0, 0)
        if c is None:
            self.misses += 1
            return None
        if self.last is not None and self.misses == 0:
            self.velocity = c - self.last
        self.misses = 0
        self.last = c
        return c


# --------------------------------------------------------------------------- entry point


def track_video(
    path: Path,
    *,
    marker_dict: str | None = None,
    marker_id: int | None = None,
    fps: float | None = None,
    progress: ProgressFn | None = None,
    still_stop_s: float = 1.0,
) -> Track:
    """Track the target through a video.

    Args:
        path: any video OpenCV reads.
        marker_dict: track an ArUco/AprilTag marker of this dictionary instead
            of the markerless target.
        marker_id: which marker (default: the first one seen).
        fps: frame rate override (default: from the container).
        progress: called as ``progress(frames_read, frames_total)``.
        still_stop_s: stop reading once the target has moved and then been
            still this long (0 reads to the end).

    Raises:
        InputError: unreadable file, no moving object, target lost at once.
    """
    video = VideoFrames(path)
    rate = fps if fps is not None else video.fps
    if rate <= 0:
        video.close()
        raise InputError(f"{path}: the video has no frame rate; give --fps")
    total = video.frame_count
    frames = iter(video)
    try:
        if marker_dict is None:
            tracker = _BackgroundTracker(video.size)
            centres, end, size_px, n_read, noise = tracker.run(
                frames, path, progress, total, still_stop_s, rate
            )
            method: Literal["background", "marker"] = "background"
        else:
            from ffexp.friction.synth import aruco_dictionary

            mt = _MarkerTracker(aruco_dictionary(marker_dict), marker_id, video.size)
            centres = []
            end = "end_of_video"
            n_read = 0
            seen = False
            for raw in frames:
                n_read += 1
                if progress is not None:
                    progress(n_read, total)
                c = mt.measure(raw)
                centres.append(c)
                seen = seen or c is not None
                if seen and mt.misses > 3:
                    end = "left_frame"
                    break
            if not seen:
                raise InputError(f"{path}: no {marker_dict} marker found in any frame")
            size_px = float(np.median(mt.sides))
            noise = 0.0
            method = "marker"
    finally:
        frames.close()  # stops the read-ahead thread
        video.close()
    n = len(centres)
    t_s = np.arange(n, dtype=np.float64) / rate
    centre_px = np.full((n, 2), np.nan)
    valid = np.zeros(n, bool)
    for i, c in enumerate(centres):
        if c is not None:
            centre_px[i] = c
            valid[i] = True
    return Track(
        video=str(path),
        fps=rate,
        frame_size=video.size,
        t_s=t_s,
        centre_px=centre_px,
        valid=valid,
        end=end,
        method=method,
        size_px=size_px,
        frames_read=n_read,
        noise_grey=noise,
    )


# --------------------------------------------------------------------------- scale


def homography_from_points(image_px: FloatArray, table_m: FloatArray) -> FloatArray:
    """Homography mapping image pixels to table metres from four (or more) points."""
    src = np.asarray(image_px, np.float64).reshape(-1, 2)
    dst = np.asarray(table_m, np.float64).reshape(-1, 2)
    if src.shape[0] < 4 or src.shape != dst.shape:
        raise ValueError("need at least four image points and as many table points")
    hom, _ = cv2.findHomography(src, dst, 0)
    if hom is None:
        raise ValueError("the table points are degenerate (three on a line?)")
    return np.asarray(hom, np.float64)


def pixels_to_metres(
    centre_px: FloatArray, *, px_per_m: float | None = None, homography: FloatArray | None = None
) -> FloatArray:
    """Convert (N, 2) pixel positions to metres by a scale or a homography."""
    pts = np.asarray(centre_px, np.float64)
    if homography is not None:
        out = cv2.perspectiveTransform(pts.reshape(-1, 1, 2), homography)
        return np.asarray(out, np.float64).reshape(-1, 2)
    if px_per_m is None or px_per_m <= 0:
        raise ValueError("need a positive px_per_m or a homography")
    return pts / px_per_m
