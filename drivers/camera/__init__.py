"""The camera target tracker: a fiducial marker on the floating target, any OpenCV capture
source, a camera-to-table calibration (:mod:`drivers.camera.calibration`).

The names below are imported on first use (PEP 562), so that the back-end's entry
(:mod:`drivers.camera.backend`, read by :mod:`drivers.registry`) does not load OpenCV.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from drivers.camera.calibration import Calibration, load_calibration, save_calibration
    from drivers.camera.tracker import CameraTracker, MarkerGeometry, target_from_marker

__all__ = ["Calibration", "CameraTracker", "MarkerGeometry", "load_calibration",
           "save_calibration", "target_from_marker"]

_WHERE = {
    "Calibration": "calibration", "load_calibration": "calibration",
    "save_calibration": "calibration", "CameraTracker": "tracker",
    "MarkerGeometry": "tracker", "target_from_marker": "tracker",
}


def __getattr__(name: str) -> Any:
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(import_module(f"{__name__}.{module}"), name)
