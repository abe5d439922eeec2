"""The camera back-end's entry: the ``camera`` target tracker (a fiducial marker on the target
seen by any OpenCV capture source, with a camera-to-table calibration).

:class:`CameraTrackerConfig` (:mod:`drivers.camera.config`) is the rig's ``[tracker]``
table and what :class:`~drivers.camera.tracker.CameraTracker` takes. Light: OpenCV is imported
when a rig opens the camera.
"""

from __future__ import annotations

from drivers.base.backend import (
    Backend,
    OpenContext,
    OpenedRobot,
    OpenedTracker,
    TrackerBackend,
)
from drivers.camera.config import CameraTrackerConfig
from drivers.errors import ConfigError

__all__ = ["BACKEND", "CameraTrackerConfig"]


def _open_tracker(cfg: CameraTrackerConfig, ctx: OpenContext,
                  robot: OpenedRobot) -> OpenedTracker:
    from drivers.camera.tracker import CameraTracker
    from drivers.vision import load_calibration

    if cfg.calibration is None:
        raise ConfigError(ctx.source, "tracker.calibration",
                          "a camera tracker needs a calibration file (ffexp calibrate-camera)")
    calibration = load_calibration(cfg.calibration, f"{ctx.source}: tracker.calibration")
    clock = getattr(robot.robot, "now_ns", None)
    tracker = CameraTracker(cfg, calibration, clock=clock,
                            where=f"{ctx.source}: tracker.source")
    return OpenedTracker(tracker, {"camera_source": cfg.source})


BACKEND = Backend("camera", trackers=(TrackerBackend(CameraTrackerConfig, _open_tracker),))
