"""Camera-to-table calibration: image pixels to the horizontal plane of the marker.

A calibration file (TOML) holds either a homography or a camera's intrinsics
and extrinsics; both come down to a homography from (undistorted) pixels to
``(x, y)`` in the robot's base frame on the plane ``z = plane_z_m`` (the
marker's top face)::

    plane_z_m = 0.05
    [homography]                 # pixels -> base-frame metres on the plane
    matrix = [[...], [...], [...]]

    # or
    plane_z_m = 0.05
    [intrinsics]
    camera_matrix = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]
    dist_coeffs = [k1, k2, p1, p2, k3]
    [extrinsics]                 # base frame -> camera frame: x_cam = R x_base + t
    rvec = [rx, ry, rz]          # Rodrigues vector [rad]
    tvec = [tx, ty, tz]          # [m]

``ffexp calibrate-camera`` writes the first form from reference points.
Pure maths plus the file's reading and writing.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from drivers.base.types import F64
from drivers.config import not_regular
from drivers.errors import ConfigError

__all__ = ["Calibration", "calibration_from_points", "load_calibration", "save_calibration"]


@dataclass(frozen=True)
class Calibration:
    """Pixels to the marker plane: ``homography`` (3x3, undistorted pixels to base-frame
    ``x, y`` [m]) at height ``plane_z_m``; ``camera_matrix``/``dist_coeffs`` when the
    image must be undistorted first."""

    homography: F64
    plane_z_m: float = 0.0
    camera_matrix: F64 | None = None
    dist_coeffs: F64 | None = None

    def to_plane(self, pixels: F64) -> F64:
        """(N, 2) pixels to (N, 2) plane coordinates [m]."""
        pts: np.ndarray = np.asarray(pixels, np.float64).reshape(-1, 1, 2)
        if self.camera_matrix is not None:
            pts = np.asarray(cv2.undistortPoints(pts, self.camera_matrix, self.dist_coeffs,
                                                 P=self.camera_matrix))
        out = cv2.perspectiveTransform(pts, self.homography)
        return np.asarray(out, np.float64).reshape(-1, 2)


def _matrix(value: object, shape: tuple[int, ...], where: str, field: str) -> F64:
    try:
        arr = np.asarray(value, np.float64)
    except (TypeError, ValueError):
        raise ConfigError(where, field, "not a numeric array") from None
    if arr.shape != shape or not np.isfinite(arr).all():
        raise ConfigError(where, field, f"needs {shape} finite numbers, got shape {arr.shape}")
    return arr


def from_extrinsics(camera_matrix: F64, rvec: F64, tvec: F64, plane_z_m: float) -> F64:
    """The pixels-to-plane homography of a pinhole camera for the plane ``z = plane_z_m``."""
    rot, _ = cv2.Rodrigues(np.asarray(rvec, np.float64).reshape(3))
    t = np.asarray(tvec, np.float64).reshape(3)
    plane_to_px = camera_matrix @ np.column_stack([rot[:, 0], rot[:, 1], rot[:, 2] * plane_z_m + t])
    out = np.asarray(np.linalg.inv(plane_to_px), np.float64)
    return np.asarray(out / out[2, 2], np.float64)


def load_calibration(path: Path, where: str) -> Calibration:
    """Read a calibration file; errors name ``where`` (the rig field) and the file's field."""
    src = f"{where}: {path}"
    odd = not_regular(path)
    if odd:
        raise ConfigError(src, "", f"is {odd}, not a regular TOML file")
    try:
        data = tomllib.loads(path.read_text())
    except OSError as exc:
        raise ConfigError(src, "", f"cannot read: {exc.strerror or exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(src, "", f"not TOML: {exc}") from None
    plane_z = data.get("plane_z_m", 0.0)
    if not isinstance(plane_z, int | float):
        raise ConfigError(src, "plane_z_m", "must be a number [m]")
    if "homography" in data:
        hom = _matrix(data["homography"].get("matrix"), (3, 3), src, "homography.matrix")
        if abs(np.linalg.det(hom)) < 1e-18:
            raise ConfigError(src, "homography.matrix", "is singular")
        return Calibration(hom, float(plane_z))
    if "intrinsics" in data and "extrinsics" in data:
        k = _matrix(data["intrinsics"].get("camera_matrix"), (3, 3), src,
                    "intrinsics.camera_matrix")
        dist = np.asarray(data["intrinsics"].get("dist_coeffs", [0.0] * 5), np.float64)
        rvec = _matrix(data["extrinsics"].get("rvec"), (3,), src, "extrinsics.rvec")
        tvec = _matrix(data["extrinsics"].get("tvec"), (3,), src, "extrinsics.tvec")
        return Calibration(from_extrinsics(k, rvec, tvec, float(plane_z)), float(plane_z), k,
                           dist)
    raise ConfigError(src, "", "needs a [homography] table, or [intrinsics] and [extrinsics]")


def save_calibration(path: Path, homography: F64, plane_z_m: float, comment: str = "") -> None:
    """Write a homography calibration file (its directory is made if missing)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    rows = ", ".join("[" + ", ".join(repr(float(v)) for v in row) + "]" for row in homography)
    head = "".join(f"# {line}\n" for line in comment.splitlines())
    path.write_text(f"{head}plane_z_m = {float(plane_z_m)!r}\n\n[homography]\n"
                    f"matrix = [{rows}]\n")


def calibration_from_points(pixels: F64, plane_m: F64) -> F64:
    """Pixels-to-plane homography from four or more reference points (least squares).

    Raises:
        ValueError: fewer than four pairs, or degenerate points.
    """
    src = np.asarray(pixels, np.float64).reshape(-1, 2)
    dst = np.asarray(plane_m, np.float64).reshape(-1, 2)
    if src.shape[0] < 4 or src.shape != dst.shape:
        raise ValueError("needs at least four pixel points and as many table points")
    hom, _ = cv2.findHomography(src, dst, 0)
    if hom is None:
        raise ValueError("the points are degenerate (three on a line?)")
    return np.asarray(hom, np.float64)
