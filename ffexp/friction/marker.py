"""Marker tracking: an ArUco/AprilTag marker of a given dictionary, detected
with sub-pixel corner refinement in a window around the last detection; its
centre is the intersection of the diagonals. Detection is the camera
tracker's (:mod:`drivers.vision.marker`): one implementation for both.
"""

from __future__ import annotations

import cv2
import numpy as np

from drivers.base.types import F64
from drivers.vision import marker as vision_marker
from drivers.vision.marker import diagonal_centre
from ffexp.errors import InputError
from ffexp.friction.video import Frame, to_grey

__all__ = ["MarkerTracker", "aruco_dictionary", "diagonal_centre"]


def aruco_dictionary(name: str) -> cv2.aruco.Dictionary:
    """An OpenCV predefined ArUco/AprilTag dictionary by name (``DICT_4X4_50``, ...)."""
    try:
        return vision_marker.aruco_dictionary(name)
    except ValueError as exc:
        raise InputError(str(exc)) from None


class MarkerTracker:
    def __init__(
        self, dictionary: cv2.aruco.Dictionary, marker_id: int | None, size: tuple[int, int]
    ) -> None:
        self.detector = vision_marker.detector(dictionary)
        self.marker_id = marker_id
        self.w, self.h = size
        self.last: F64 | None = None
        self.side_px = 0.0
        self.sides: list[float] = []
        self.velocity: F64 = np.zeros(2)
        self.misses = 0

    def _detect(self, frame: Frame, u0: int, v0: int) -> F64 | None:
        found = vision_marker.find_marker(self.detector, to_grey(frame), self.marker_id)
        if found is None:
            return None
        self.marker_id, quad = found
        quad = quad + np.array([u0, v0], np.float64)
        sides = np.linalg.norm(quad - np.roll(quad, -1, axis=0), axis=1)
        self.sides.append(float(sides.mean()))
        return diagonal_centre(quad)

    def measure(self, frame: Frame) -> F64 | None:
        c: F64 | None = None
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
