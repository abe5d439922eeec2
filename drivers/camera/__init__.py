"""The camera target tracker: a fiducial marker on the floating target, any OpenCV capture
source, a camera-to-table calibration (:mod:`drivers.vision.calibration`).

The names below are imported on first use (PEP 562), so that the back-end's entry
(:mod:`drivers.camera.backend`, read by :mod:`drivers.registry`) does not load OpenCV.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from drivers.camera.tracker import CameraTracker, MarkerGeometry, target_from_marker

__all__ = ["CameraTracker", "MarkerGeometry", "target_from_marker"]

_WHERE = {"CameraTracker": "tracker", "MarkerGeometry": "tracker", "target_from_marker": "tracker"}


def __getattr__(name: str) -> Any:
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(import_module(f"{__name__}.{module}"), name)
