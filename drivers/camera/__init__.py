"""The camera target tracker: a fiducial marker on the floating target, any OpenCV capture
source, a camera-to-table calibration (:mod:`drivers.camera.calibration`)."""

from drivers.camera.calibration import Calibration, load_calibration, save_calibration
from drivers.camera.tracker import CameraTracker, MarkerGeometry, target_from_marker

__all__ = ["Calibration", "CameraTracker", "MarkerGeometry", "load_calibration",
           "save_calibration", "target_from_marker"]
