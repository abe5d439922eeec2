"""From a video to ``mu``: track, scale, find the sliding window, fit.

Glue between :mod:`ffexp.friction.track` (I/O) and :mod:`ffexp.friction.fit`
(pure maths). Every user error ends as :class:`ffexp.errors.InputError`
naming the video or the file at fault.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from drivers.base.types import F64
from ffexp.errors import InputError
from ffexp.friction.fit import (
    G_MPS2,
    MIN_FIT_FRAMES,
    FitError,
    FrictionEstimate,
    SlidingInterval,
    estimate_friction,
    find_sliding_interval,
    project_on_motion,
    robust_noise,
    trim_at_fitted_stop,
)
from ffexp.friction.track import (
    ProgressFn,
    Track,
    homography_from_points,
    pixels_to_metres,
    track_video,
)


@dataclass(frozen=True)
class Scale:
    """How pixels become metres: exactly one of the three."""

    px_per_m: float | None = None
    object_size_m: float | None = None
    table_points: Path | None = None

    def __post_init__(self) -> None:
        given = [x is not None for x in (self.px_per_m, self.object_size_m, self.table_points)]
        if sum(given) != 1:
            raise InputError(
                "give exactly one scale: --px-per-m, --object-size-m or --table-points"
            )
        for name, value in (("--px-per-m", self.px_per_m), ("--object-size-m", self.object_size_m)):
            if value is not None and not (math.isfinite(value) and value > 0):
                raise InputError(f"{name} must be a positive number, not {value}")


def load_table_points(path: Path) -> tuple[F64, F64]:
    """Read ``{"image_px": [[u, v] x4+], "table_m": [[x, y] x4+]}`` from JSON.

    Raises:
        InputError: missing, unreadable or malformed file (naming it).
    """
    from drivers.config import not_regular

    odd = not_regular(path)
    if odd:
        raise InputError(f"{path}: is {odd}, not a regular JSON file")
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        img = np.asarray(doc["image_px"], np.float64)
        tab = np.asarray(doc["table_m"], np.float64)
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise InputError(f"{path}: is a directory, expected a JSON file") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{path}: cannot read table points ({exc})") from None
    except (KeyError, TypeError, ValueError):
        raise InputError(
            f'{path}: expected {{"image_px": [[u, v], ...], "table_m": [[x, y], ...]}}'
        ) from None
    if img.ndim != 2 or img.shape[1] != 2 or img.shape != tab.shape or img.shape[0] < 4:
        raise InputError(f"{path}: need the same number (>= 4) of image_px and table_m pairs")
    if not (np.isfinite(img).all() and np.isfinite(tab).all()):
        raise InputError(f"{path}: table points must be finite numbers")
    return img, tab


@dataclass(frozen=True)
class FrictionResult:
    """Everything the estimate found, for printing, plotting and recording."""

    video: str
    track: Track
    pos_m: F64  # (N, 2), NaN where invalid
    s_m: F64  # (N,) along the motion direction, NaN where invalid
    direction: F64  # unit vector in table metres
    interval: SlidingInterval  # indices into the valid samples
    window_idx: npt.NDArray[np.intp]  # indices into the track of the fitted frames
    estimate: FrictionEstimate
    px_per_m: float | None
    scale_source: str

    def to_dict(self) -> dict[str, Any]:
        """The result as a JSON-ready dict (SI units, names carry units)."""
        e = self.estimate
        f = e.fit
        return {
            "video": self.video,
            "mu": e.mu,
            "mu_std": e.mu_std,
            "mu_low": e.mu_low,
            "mu_high": e.mu_high,
            "confidence": e.confidence,
            "mu_upper_bound": e.mu_upper_bound,
            "mu_detect_limit": e.mu_detect_limit,
            "significant": bool(e.significant),
            "decel_mps2": f.decel_mps2,
            "decel_std_mps2": f.decel_std_mps2,
            "sigma_a_formula_mps2": e.sigma_a_formula_mps2,
            "v0_mps": f.v_start_mps,
            "window_s": f.window_s,
            "window_start_s": f.t_start_s,
            "window_end_s": f.t_end_s,
            "frames_used": f.n_frames,
            "end_reason": self.interval.end_reason,
            "residual_std_m": f.residual_std_m,
            "sigma_x_m": e.sigma_x_m,
            "dof": e.dof,
            "residual_rho1": f.rho1,
            "variance_inflation": f.inflation,
            "noise_m": self.interval.noise_m,
            "direction": [float(self.direction[0]), float(self.direction[1])],
            "g_mps2": e.g_mps2,
            "px_per_m": self.px_per_m,
            "scale_source": self.scale_source,
            "method": self.track.method,
            "fps": self.track.fps,
            "frames_read": self.track.frames_read,
            "tracking_end": self.track.end,
        }

    def summary(self) -> str:
        """Two human-readable lines."""
        e = self.estimate
        f = e.fit
        pct = round(100 * e.confidence)
        head = (
            f"mu = {e.mu:.5f} ± {e.mu_std:.5f} ({pct}%: [{e.mu_low:.5f}, {e.mu_high:.5f}])"
            if e.significant
            else f"mu < {e.mu_upper_bound:.5f} ({pct}% upper bound; a is not significant: "
            f"mu = {e.mu:.5f} ± {e.mu_std:.5f})"
        )
        tail = (
            f"decel {f.decel_mps2:.5f} ± {f.decel_std_mps2:.5f} m/s², v0 {f.v_start_mps:.4f} m/s, "
            f"{f.n_frames} frames over {f.window_s:.3f} s "
            f"[{f.t_start_s:.3f}, {f.t_end_s:.3f}] s, ended: {self.interval.end_reason}, "
            f"residual {f.residual_std_m * 1e6:.1f} µm, detectable mu {e.mu_detect_limit:.5f}"
        )
        if e.mu_high < 0.0:
            tail += "\nwarning: the target speeds up (a tilted table or a push?)"
        return head + "\n" + tail


def estimate_video(
    path: Path,
    scale: Scale,
    *,
    marker_dict: str | None = None,
    marker_id: int | None = None,
    start_s: float | None = None,
    end_s: float | None = None,
    fps: float | None = None,
    g_mps2: float = G_MPS2,
    confidence: float = 0.95,
    progress: ProgressFn | None = None,
) -> FrictionResult:
    """Estimate the friction coefficient from a video of the target sliding.

    Args:
        path: the video.
        scale: pixels to metres.
        marker_dict: track this ArUco/AprilTag dictionary's marker instead.
        marker_id: which marker.
        start_s: start of the fit window (s); default automatic.
        end_s: end of the fit window (s); default automatic.
        fps: frame-rate override.
        g_mps2: gravity.
        confidence: two-sided confidence of the interval.
        progress: progress callback ``(done, total)``.

    Raises:
        InputError: anything wrong with the inputs, naming the file.
    """
    table: tuple[F64, F64] | None = None
    if scale.table_points is not None:
        table = load_table_points(scale.table_points)
    # stop early only when the window is automatic at the end
    track = track_video(
        path,
        marker_dict=marker_dict,
        marker_id=marker_id,
        fps=fps,
        progress=progress,
        still_stop_s=1.0 if end_s is None else 0.0,
    )
    if scale.px_per_m is not None:
        px_per_m: float | None = scale.px_per_m
        homography = None
        source = "px_per_m"
    elif scale.object_size_m is not None:
        px_per_m = track.size_px / scale.object_size_m
        homography = None
        source = "object_size_m"
    else:
        assert table is not None
        try:
            homography = homography_from_points(*table)
        except ValueError as exc:
            raise InputError(f"{scale.table_points}: {exc}") from None
        px_per_m = None
        source = "homography"
    idx = np.flatnonzero(track.valid)
    # the track is contiguous from its first valid sample; keep that run
    if idx.size:
        breaks = np.flatnonzero(np.diff(idx) > 1)
        if breaks.size:
            idx = idx[: breaks[0] + 1]
    if idx.size < MIN_FIT_FRAMES + 1:
        raise InputError(f"{path}: the target is tracked in only {idx.size} frames")
    pos = pixels_to_metres(track.centre_px[idx], px_per_m=px_per_m, homography=homography)
    t = track.t_s[idx]
    try:
        s, direction = project_on_motion(pos)
        if start_s is not None and end_s is not None:
            # both ends given: no automatic detection needed (nor allowed to fail)
            interval = SlidingInterval(
                start=0, end=t.size - 1, end_reason="user", onset=0, noise_m=robust_noise(s)
            )
        else:
            interval = find_sliding_interval(t, s, left_frame=track.left_frame)
            interval = trim_at_fitted_stop(t, s, interval)
        lo, hi = interval.start, interval.end
        if start_s is not None or end_s is not None:
            t0 = t[lo] if start_s is None else start_s
            t1 = t[hi] if end_s is None else end_s
            sel = np.flatnonzero((t >= t0 - 1e-9) & (t <= t1 + 1e-9))
            if sel.size < MIN_FIT_FRAMES:
                raise FitError(
                    f"the window [{t0:.3f}, {t1:.3f}] s holds {sel.size} tracked frame(s) "
                    f"(need at least {MIN_FIT_FRAMES})"
                )
            lo, hi = int(sel[0]), int(sel[-1])
            interval = SlidingInterval(
                start=lo, end=hi, end_reason="user", onset=interval.onset, noise_m=interval.noise_m
            )
        # the tracking noise from every frame after the onset (slide and rest):
        # robust, from second differences; the MAD has ~37 % efficiency
        tail = s[interval.onset :]
        noise_dof = 0.37 * (tail.size - 2) if tail.size >= 8 else 0.0
        est = estimate_friction(
            t[lo : hi + 1],
            s[lo : hi + 1],
            g_mps2=g_mps2,
            confidence=confidence,
            noise_m=robust_noise(tail) if noise_dof else None,
            noise_dof=noise_dof,
        )
    except FitError as exc:
        raise InputError(f"{path}: {exc}") from None
    n = track.t_s.size
    pos_all = np.full((n, 2), np.nan)
    pos_all[idx] = pos
    s_all = np.full(n, np.nan)
    s_all[idx] = s
    return FrictionResult(
        video=str(path),
        track=track,
        pos_m=pos_all,
        s_m=s_all,
        direction=direction,
        interval=interval,
        window_idx=idx[lo : hi + 1].astype(np.intp),
        estimate=est,
        px_per_m=px_per_m,
        scale_source=source,
    )
