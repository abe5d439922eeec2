"""The camera back-end's rig table: the ``camera`` target tracker.

Each model is what the back-end's device takes as it is (no second settings class);
its fields are spelled as the rig file spells them. Light: pydantic only.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

from pydantic import Field

from drivers.base.backend import DeviceConfig
from drivers.config import NonNeg, PosFloat, Vec3

__all__ = ["CameraTrackerConfig"]


class CameraTrackerConfig(DeviceConfig):
    """A camera above the air bed tracking a fiducial marker on the target."""

    type: Literal["camera"] = "camera"
    source: str = "0"
    """OpenCV capture source: a device index (``"0"``), a video file or a URL
    (``http://host:port/stream.mjpg``)."""
    calibration: Path | None = None
    """Camera-to-table calibration TOML (``ffexp calibrate-camera``), relative to the rig file."""
    marker_dictionary: str = "DICT_4X4_50"
    """OpenCV ArUco/AprilTag dictionary of the marker."""
    marker_id: Annotated[int, Field(ge=0)] = 0
    marker_in_target_m: Vec3 = (0.0, 0.0, 0.025)
    """Marker centre in the target block frame [m] (default: centre of its top face)."""
    marker_yaw_deg: float = 0.0
    """Marker's x axis against the target's x axis, about the vertical [deg]."""
    mouth_in_target_m: Vec3 = (-0.125, 0.0, 0.073)
    """Target funnel's mouth centre in the target block frame [m] (the paper's
    block: mid-face of the -x side); the mouth frame is the block's, rotated not."""
    latency_s: NonNeg = 0.0
    """From exposure to the frame's arrival; subtracted from the arrival time."""
    lost_after_s: PosFloat = 1.0
    """No frame for this long: the stream is lost (an event; the capture reopens)."""
    reopen_s: PosFloat = 1.0
    """Wait between attempts to (re)open the source."""
