"""Find and track the target in a video; convert pixels to metres.

Two trackers, both sub-pixel:

- **background** (markerless, the default; :mod:`ffexp.friction.markerless`):
  a background model from the first still frames, the target segmented in it
  where the motion starts, then the centroid of the relative contrast to the
  empty table in a window that follows the target;
- **marker** (:mod:`ffexp.friction.marker`): an ArUco/AprilTag marker of a
  given dictionary, detected with sub-pixel corner refinement; the centre is
  the intersection of the diagonals.

Frames come from :mod:`ffexp.friction.video`; pixels become metres in
:mod:`ffexp.friction.homography`. This module holds :class:`Track` and the
entry point :func:`track_video`, and re-exports the public names of the
others, so ``from ffexp.friction.track import ...`` keeps working.

Pixel ``(u, v)`` has its centre at integer ``(u, v)`` (OpenCV convention).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
import numpy.typing as npt

from drivers.base.types import F64
from ffexp.errors import InputError
from ffexp.friction.homography import homography_from_points, pixels_to_metres
from ffexp.friction.marker import MarkerTracker, aruco_dictionary, diagonal_centre
from ffexp.friction.markerless import BackgroundTracker, fill_smooth
from ffexp.friction.video import (
    Frame,
    Grey8,
    GreyF,
    ProgressFn,
    TrackEnd,
    VideoFrames,
    quiet_opencv,
)

__all__ = [
    "F64",
    "Frame",
    "Grey8",
    "GreyF",
    "ProgressFn",
    "Track",
    "TrackEnd",
    "VideoFrames",
    "diagonal_centre",
    "fill_smooth",
    "homography_from_points",
    "pixels_to_metres",
    "quiet_opencv",
    "track_video",
]


@dataclass
class Track:
    """Per-frame target centre in pixels, with validity."""

    video: str
    fps: float
    frame_size: tuple[int, int]
    t_s: F64
    centre_px: F64
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
            tracker = BackgroundTracker(video.size)
            centres, end, size_px, n_read, noise = tracker.run(
                frames, path, progress, total, still_stop_s, rate
            )
            method: Literal["background", "marker"] = "background"
        else:
            mt = MarkerTracker(aruco_dictionary(marker_dict), marker_id, video.size)
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
