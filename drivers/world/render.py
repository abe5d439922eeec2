"""The simulated target seen from above by a camera, with its fiducial marker.

A top view is a homography from the horizontal plane of the target's top face
(world ``x, y`` [m]) to pixels: :func:`top_view` builds one for a camera
looking straight down, centred on a point of the bed. :class:`TargetRenderer`
draws the bed (uniform grey), the block's top face and an ArUco/AprilTag
marker with a white quiet zone on it (OpenCV's marker image, warped by the
composed homography, bilinear). The camera tracker reads the same marker back
(the test of ``drivers/camera``); the emulator serves these frames as a stream.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from drivers.base.types import F64

__all__ = ["TargetRenderer", "top_view"]


def top_view(centre_xy_m: tuple[float, float], px_per_m: float,
             size_px: tuple[int, int]) -> F64:
    """Plane-to-pixel homography of a camera looking down at ``centre_xy_m``: world +x
    is up in the image and +y to the left (seen from above, z toward the camera)."""
    w, h = size_px
    u0, v0 = (w - 1) / 2.0, (h - 1) / 2.0
    cx, cy = centre_xy_m
    s = px_per_m
    return np.array([[0.0, -s, u0 + s * cy], [-s, 0.0, v0 + s * cx], [0.0, 0.0, 1.0]])


class TargetRenderer:
    """Frames of the target's top face and marker.

    Args:
        plane_to_px: homography from the top face's plane (world x, y) to pixels.
        size_px: ``(width, height)``.
        block_m: the block's top face ``(x, y)`` size [m].
        marker_dictionary: OpenCV ArUco dictionary (``cv2.aruco.DICT_4X4_50``'s name).
        marker_id, marker_m: the marker and its side (black border included) [m].
        marker_in_target_xy_m: the marker centre on the top face, block frame [m].
        noise: standard deviation of Gaussian pixel noise (grey levels), seeded.
    """

    def __init__(self, plane_to_px: F64, size_px: tuple[int, int], block_m: tuple[float, float],
                 marker_dictionary: str = "DICT_4X4_50", marker_id: int = 0,
                 marker_m: float = 0.12, marker_in_target_xy_m: tuple[float, float] = (0.0, 0.0),
                 noise: float = 0.0, seed: int = 0) -> None:
        self.g = np.asarray(plane_to_px, np.float64)
        self.w, self.h = size_px
        self.block = block_m
        ident = getattr(cv2.aruco, marker_dictionary.upper())
        dic = cv2.aruco.getPredefinedDictionary(ident)
        cells = dic.markerSize + 2
        px = cells * 24
        marker = cv2.aruco.generateImageMarker(dic, marker_id, px)
        quiet = px // cells  # one cell of white around the black border
        self.image = cv2.copyMakeBorder(marker, quiet, quiet, quiet, quiet,
                                        cv2.BORDER_CONSTANT, value=255)
        n = self.image.shape[0]
        side = marker_m * n / px  # the quiet zone is printed too
        # marker image pixel (u, v) -> marker plane (x right, y up), pixel centres
        self.img_to_marker = np.array([[side / n, 0.0, side * (0.5 / n - 0.5)],
                                       [0.0, -side / n, side * (0.5 - 0.5 / n)],
                                       [0.0, 0.0, 1.0]])
        self.marker_xy = marker_in_target_xy_m
        self.noise = noise
        self.rng = np.random.default_rng(seed)
        self.bed = np.full((self.h, self.w), 90, np.uint8)

    def render(self, target_pose: F64) -> np.ndarray:
        """A BGR frame of the target at ``target_pose`` (4x4, world; yaw about z only)."""
        yaw = math.atan2(target_pose[1, 0], target_pose[0, 0])
        c, s = math.cos(yaw), math.sin(yaw)
        tx, ty = float(target_pose[0, 3]), float(target_pose[1, 3])
        target2d = np.array([[c, -s, tx], [s, c, ty], [0.0, 0.0, 1.0]])
        frame = self.bed.copy()
        bx, by = self.block[0] / 2.0, self.block[1] / 2.0
        corners = np.array([[bx, by, 1.0], [-bx, by, 1.0], [-bx, -by, 1.0], [bx, -by, 1.0]])
        px = (self.g @ target2d @ corners.T).T
        px = px[:, :2] / px[:, 2:3]
        cv2.fillConvexPoly(frame, np.round(px * 16).astype(np.int32), 200, cv2.LINE_AA, 4)
        mx, my = self.marker_xy
        marker2d = target2d @ np.array([[1.0, 0.0, mx], [0.0, 1.0, my], [0.0, 0.0, 1.0]])
        hom = self.g @ marker2d @ self.img_to_marker
        warped = cv2.warpPerspective(self.image, hom, (self.w, self.h), flags=cv2.INTER_LINEAR,
                                     borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        mask = cv2.warpPerspective(np.full_like(self.image, 255), hom, (self.w, self.h),
                                   flags=cv2.INTER_LINEAR, borderValue=0)
        a = mask.astype(np.float32) / 255.0
        out = frame.astype(np.float32) * (1.0 - a) + warped.astype(np.float32) * a
        if self.noise > 0.0:
            out += self.rng.normal(0.0, self.noise, out.shape).astype(np.float32)
        grey = np.clip(np.rint(out), 0, 255).astype(np.uint8)
        return np.asarray(cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR))
