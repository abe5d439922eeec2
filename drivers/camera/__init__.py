"""The camera target tracker: a fiducial marker on the floating target, any OpenCV capture
source, a camera-to-table calibration (:mod:`drivers.vision.calibration`)."""

from drivers.camera.tracker import CameraTracker, MarkerGeometry, target_from_marker

__all__ = ["CameraTracker", "MarkerGeometry", "target_from_marker"]
