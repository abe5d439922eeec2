"""Fiducial markers (ArUco/AprilTag): the one implementation the camera tracker and the
friction video tools share. OpenCV's detector with sub-pixel corner refinement."""

from __future__ import annotations

import cv2
import numpy as np

from drivers.base.types import F64

__all__ = ["aruco_dictionary", "detector", "diagonal_centre", "find_marker"]


def aruco_dictionary(name: str) -> cv2.aruco.Dictionary:
    """An OpenCV predefined ArUco/AprilTag dictionary by name (``DICT_4X4_50``, ...).

    Raises:
        ValueError: an unknown name (callers name their field or option).
    """
    key = name.upper()
    if not key.startswith("DICT_"):
        key = "DICT_" + key
    ident = getattr(cv2.aruco, key, None)
    if not isinstance(ident, int):
        raise ValueError(
            f"unknown marker dictionary {name!r} (e.g. DICT_4X4_50, DICT_APRILTAG_36h11)"
        )
    return cv2.aruco.getPredefinedDictionary(ident)


def detector(dictionary: cv2.aruco.Dictionary) -> cv2.aruco.ArucoDetector:
    """A detector refining corners to sub-pixel accuracy."""
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    params.cornerRefinementMinAccuracy = 0.005
    params.cornerRefinementMaxIterations = 50
    return cv2.aruco.ArucoDetector(dictionary, params)


def find_marker(det: cv2.aruco.ArucoDetector, grey: np.ndarray,
                marker_id: int | None) -> tuple[int, F64] | None:
    """The marker ``marker_id`` (any, if ``None``) in a grey image: its id and its four
    corners (4, 2) in pixels, in the dictionary's order (the marker's own top-left,
    top-right, bottom-right, bottom-left), or ``None``."""
    corners, ids, _ = det.detectMarkers(np.ascontiguousarray(grey))
    if ids is None or len(ids) == 0:
        return None
    flat = [int(i) for i in np.asarray(ids).ravel()]
    if marker_id is None:
        marker_id = flat[0]
    if marker_id not in flat:
        return None
    quad = np.asarray(corners[flat.index(marker_id)], np.float64).reshape(4, 2)
    return marker_id, quad


def diagonal_centre(corners: F64) -> F64:
    """Intersection of the diagonals of a quadrilateral (4, 2)."""
    p0, p1, p2, p3 = (np.asarray(c, np.float64) for c in corners)
    d1 = p2 - p0
    d2 = p3 - p1
    mat = np.array([[d1[0], -d2[0]], [d1[1], -d2[1]]])
    if abs(np.linalg.det(mat)) < 1e-12:
        return np.asarray(corners, np.float64).mean(axis=0)  # type: ignore[no-any-return]
    lam, _ = np.linalg.solve(mat, p1 - p0)
    return p0 + lam * d1  # type: ignore[no-any-return]
