"""Marker tracking: an ArUco/AprilTag marker of a given dictionary, detected
with sub-pixel corner refinement in a window around the last detection; its
centre is the intersection of the diagonals.
"""

from __future__ import annotations

import cv2
import numpy as np

from drivers.base.types import F64 as FloatArray
from ffexp.errors import InputError
from ffexp.friction.video import Frame, to_grey


def aruco_dictionary(name: str) -> cv2.aruco.Dictionary:
    """An OpenCV predefined ArUco/AprilTag dictionary by name (``DICT_4X4_50``, ...)."""
    key = name.upper()
    if not key.startswith("DICT_"):
        key = "DICT_" + key
    ident = getattr(cv2.aruco, key, None)
    if not isinstance(ident, int):
        raise InputError(
            f"unknown marker dictionary {name!r} (e.g. DICT_4X4_50, DICT_APRILTAG_36h11)"
        )
    return cv2.aruco.getPredefinedDictionary(ident)


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


class MarkerTracker:
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
        corners, ids, _ = self.detector.detectMarkers(np.ascontiguousarray(to_grey(frame)))
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
