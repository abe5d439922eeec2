"""Pixels to metres: a uniform scale, or a homography from four or more
image points with known table coordinates."""

from __future__ import annotations

import cv2
import numpy as np

from drivers.base.types import F64
from drivers.vision.calibration import calibration_from_points


def homography_from_points(image_px: F64, table_m: F64) -> F64:
    """Homography mapping image pixels to table metres from four (or more) points
    (the camera calibration's fit, :func:`drivers.vision.calibration.calibration_from_points`)."""
    return calibration_from_points(image_px, table_m)


def pixels_to_metres(
    centre_px: F64, *, px_per_m: float | None = None, homography: F64 | None = None
) -> F64:
    """Convert (N, 2) pixel positions to metres by a scale or a homography."""
    pts = np.asarray(centre_px, np.float64)
    if homography is not None:
        out = cv2.perspectiveTransform(pts.reshape(-1, 1, 2), homography)
        return np.asarray(out, np.float64).reshape(-1, 2)
    if px_per_m is None or px_per_m <= 0:
        raise ValueError("need a positive px_per_m or a homography")
    return pts / px_per_m
