"""The ``camera`` target tracker: a fiducial marker on the target, seen by any OpenCV capture.

The capture runs in its own daemon thread: it opens the source (a device
index, a video file or a network stream such as an MJPEG-over-HTTP URL),
decodes frames, finds the marker (:mod:`drivers.vision.marker`), maps its
corners to the table plane (:mod:`drivers.vision.calibration`) and publishes
the target's pose; :meth:`CameraTracker.latest` only reads the newest
observation under a lock, so the control loop never waits for the camera.

A frame's time is its arrival on the robot's clock minus ``latency_s``. A
frame without the marker publishes an invalid observation (``status``
``"marker not found"``); no frame for ``lost_after_s`` (or a source that ends
or cannot be opened) publishes ``"stream lost: ..."`` and the thread reopens
the source every ``reopen_s`` until stopped. Network reads time out after
``lost_after_s`` (FFmpeg's read timeout), and :meth:`CameraTracker.latest`
itself reports a stream that has been silent that long, should a read hang.
:meth:`CameraTracker.stop` releases the capture within one read timeout.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable

import cv2
import numpy as np

from drivers.base.interfaces import TargetTracker
from drivers.base.types import F64, NS_PER_S, TargetObservation
from drivers.camera.config import CameraTrackerConfig
from drivers.errors import ConfigError
from drivers.vision.calibration import Calibration
from drivers.vision.marker import aruco_dictionary, detector, find_marker

__all__ = ["CameraTracker", "MarkerGeometry", "target_from_marker"]


def _rz(yaw: float) -> F64:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


class MarkerGeometry:
    """Where the marker and the funnel mouth are on the target (block frame)."""

    def __init__(self, marker_in_target_m: tuple[float, float, float], marker_yaw_deg: float,
                 mouth_in_target_m: tuple[float, float, float]) -> None:
        marker = np.eye(4)
        marker[:3, :3] = _rz(math.radians(marker_yaw_deg))
        marker[:3, 3] = marker_in_target_m
        self.target_in_marker: F64 = np.asarray(np.linalg.inv(marker), np.float64)
        self.mouth_in_target: F64 = np.eye(4)
        self.mouth_in_target[:3, 3] = mouth_in_target_m


def target_from_marker(quad_px: F64, calibration: Calibration,
                       geometry: MarkerGeometry) -> tuple[F64, F64]:
    """The target block's pose and its funnel mouth's frame (4x4, base frame) from the
    marker's four corners in pixels (dictionary order). Pure maths."""
    plane = calibration.to_plane(quad_px)
    centre = plane.mean(axis=0)  # a square's corners: the mean is its centre on the plane
    x_axis = (plane[1] - plane[0]) + (plane[2] - plane[3])  # the marker's own +x, both edges
    marker = np.eye(4)
    marker[:3, :3] = _rz(math.atan2(x_axis[1], x_axis[0]))
    marker[:3, 3] = (centre[0], centre[1], calibration.plane_z_m)
    target = marker @ geometry.target_in_marker
    return target, target @ geometry.mouth_in_target


def _open_source(source: str, timeout_s: float) -> cv2.VideoCapture:
    """A capture of a device index, a file, or a URL (FFmpeg, with open and read timeouts
    so that a silent stream ends a read instead of blocking it)."""
    if source.isdigit():
        return cv2.VideoCapture(int(source))
    if "://" in source:
        ms = max(1, round(timeout_s * 1000))
        return cv2.VideoCapture(source, cv2.CAP_FFMPEG, [
            cv2.CAP_PROP_OPEN_TIMEOUT_MSEC, ms, cv2.CAP_PROP_READ_TIMEOUT_MSEC, ms])
    return cv2.VideoCapture(source)


class CameraTracker(TargetTracker):
    """The target's pose from a camera; see the module's docstring.

    Args:
        cfg: the rig's ``[tracker]`` table.
        calibration: pixels to the marker plane.
        clock: the robot's time now [ns] (``None`` or returning ``None``: monotonic time).
        where: names the source in messages (the rig file and ``tracker.source``).
        on_frame: called with each observation as it is published (tests, statistics).
    """

    source_name = "camera"

    def __init__(self, cfg: CameraTrackerConfig, calibration: Calibration, *,
                 clock: Callable[[], int | None] | None = None, where: str = "tracker.source",
                 on_frame: Callable[[TargetObservation], None] | None = None) -> None:
        try:
            self._detector = detector(aruco_dictionary(cfg.marker_dictionary))
        except ValueError as exc:
            raise ConfigError(where.rsplit(":", 1)[0], "tracker.marker_dictionary",
                              str(exc)) from None
        self.source = str(cfg.source)
        self.marker_id = int(cfg.marker_id)
        self.calibration = calibration
        self.geometry = MarkerGeometry(cfg.marker_in_target_m, cfg.marker_yaw_deg,
                                       cfg.mouth_in_target_m)
        self.latency_ns = round(cfg.latency_s * NS_PER_S)
        self.lost_after_s = float(cfg.lost_after_s)
        self.reopen_s = float(cfg.reopen_s)
        self.where = where
        self._clock = clock
        self._on_frame = on_frame
        self._cond = threading.Condition()
        self._latest: TargetObservation | None = None
        self._last_valid: TargetObservation | None = None
        self._frames = 0
        self._published_at = time.monotonic()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.marker_misses = 0
        self.stream_losses = 0

    # -- time ------------------------------------------------------------------
    def _now_ns(self) -> int:
        t = self._clock() if self._clock is not None else None
        return t if t is not None else time.monotonic_ns()

    # -- lifecycle ---------------------------------------------------------------
    def start(self) -> None:
        if self._thread is not None:
            return
        self._stop.clear()
        self._publish(self._invalid(self._now_ns(), "no frame yet"))
        self._thread = threading.Thread(target=self._run, name="camera-tracker", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        thread, self._thread = self._thread, None
        if thread is not None:
            thread.join(timeout=self.lost_after_s + 5.0)

    def latest(self) -> TargetObservation | None:
        """The newest observation; if the capture has published nothing for
        ``lost_after_s`` (a stalled stream, a read that hangs), an invalid one saying so."""
        with self._cond:
            obs = self._latest
            silent = time.monotonic() - self._published_at
            reported = not obs.valid and obs.status.startswith("stream lost") if obs else True
            if reported or silent <= self.lost_after_s or self._thread is None:
                return obs
        self._lost(f"no frame for {silent:.1f} s")
        return self.latest()

    def wait(self, timeout_s: float, *, valid: bool = True) -> TargetObservation | None:
        """Block until an observation (a valid one, unless ``valid`` is false) newer than
        the current one arrives, or ``timeout_s``; for tools and tests, not the loop."""
        deadline = time.monotonic() + timeout_s
        with self._cond:
            seen = self._frames
            while True:
                obs = self._latest
                if obs is not None and self._frames > seen and (obs.valid or not valid):
                    return obs
                left = deadline - time.monotonic()
                if left <= 0 or not self._cond.wait(left):
                    return None

    # -- the capture thread ------------------------------------------------------
    def _invalid(self, t_ns: int, status: str) -> TargetObservation:
        last = self._last_valid
        pose = last.pose_m if last is not None else np.eye(4)
        mouth = last.mouth_m if last is not None else np.eye(4)
        return TargetObservation(t_ns, pose, mouth, False, self.source_name, self._frames, status)

    def _publish(self, obs: TargetObservation) -> None:
        with self._cond:
            self._published_at = time.monotonic()
            self._frames += 1
            obs.frames = self._frames
            self._latest = obs
            if obs.valid:
                self._last_valid = obs
            self._cond.notify_all()
        if self._on_frame is not None:
            self._on_frame(obs)

    def process(self, frame: np.ndarray, t_ns: int) -> TargetObservation:
        """One frame taken at ``t_ns``: the observation it gives (published too)."""
        grey = frame if frame.ndim == 2 else cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
        found = find_marker(self._detector, grey, self.marker_id)
        if found is None:
            self.marker_misses += 1
            obs = self._invalid(t_ns, "marker not found")
        else:
            target, mouth = target_from_marker(found[1], self.calibration, self.geometry)
            obs = TargetObservation(t_ns, target, mouth, True, self.source_name, 0)
        self._publish(obs)
        return obs

    def _run(self) -> None:
        while not self._stop.is_set():
            cap = _open_source(self.source, self.lost_after_s)
            if not cap.isOpened():
                cap.release()
                self._lost(f"cannot open {self.source}")
                self._stop.wait(self.reopen_s)
                continue
            self._read_all(cap)
            cap.release()
            if not self._stop.is_set():
                self._stop.wait(self.reopen_s)

    def _lost(self, why: str) -> None:
        self.stream_losses += 1
        self._publish(self._invalid(self._now_ns(), f"stream lost: {why} ({self.where})"))

    def _read_all(self, cap: cv2.VideoCapture) -> None:
        """Frames until the source ends, stalls past ``lost_after_s``, or stop."""
        last_ok = time.monotonic()
        while not self._stop.is_set():
            ok, frame = cap.read()
            arrived = self._now_ns()
            if not ok or frame is None:
                if time.monotonic() - last_ok > self.lost_after_s or not self._is_live():
                    self._lost("no frames" if self._is_live() else "end of the source")
                    return
                continue
            last_ok = time.monotonic()
            self.process(frame, arrived - self.latency_ns)

    def _is_live(self) -> bool:
        return "://" in self.source or self.source.isdigit()
