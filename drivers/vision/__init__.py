"""Camera geometry shared by the camera tracker and ``ffexp.friction``: fiducial markers
(:mod:`drivers.vision.marker`) and the camera-to-table calibration
(:mod:`drivers.vision.calibration`). Pure OpenCV geometry and the calibration file; not a
back-end (no capture, no sockets)."""

from drivers.vision.calibration import Calibration, load_calibration, save_calibration

__all__ = ["Calibration", "load_calibration", "save_calibration"]
