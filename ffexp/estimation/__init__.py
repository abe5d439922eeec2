"""The estimator of the experiment loop: everything done to the sensor signal per cycle.

Its parts, one module each (pure: no I/O): :mod:`ffexp.estimation.wrench_filter`
and :mod:`ffexp.estimation.motion_filter` (Kalman filters, filterpy),
:mod:`ffexp.estimation.tool_load` (the tool's weight and inertia and their
identification) and :mod:`ffexp.estimation.contact` (the contact detector);
:mod:`ffexp.estimation.estimator` steps N runs at once (a single run is a batch of
one) through one compiled cycle, :mod:`ffexp.estimation.kernels`.

Per cycle, from the robot state and the F/T samples that arrived since the
last cycle (pure: no I/O, no clock):

1. tool-load compensation: the tool's weight and, with
   ``inertial_compensation``, its inertia (mass x the acceleration the motion
   filter estimated up to the previous cycle) are removed from every sample;
2. the peak force and torque of the cycle's samples (bias removed once tared)
   and the sensor's saturation bit, for :class:`ffexp.safety.SafetyMonitor`;
3. the tool twist from the motion filter (the robot's pose);
4. before the tare: samples are collected; the tare runs once they cover
   ``run.tare_s`` of sensor time and the robot is commanding (whatever the
   sensor's rate); after it: the wrench Kalman filter and the contact detector.
"""

from __future__ import annotations

from ffexp.estimation.config import Estimate, Estimation
from ffexp.estimation.contact import ContactDetector, ContactDetectorConfig, ContactEvent
from ffexp.estimation.estimator import EstimateBatch, Estimator
from ffexp.estimation.motion_filter import MotionFilter, MotionFilterConfig
from ffexp.estimation.tool_load import (
    GRAVITY_BASE_MPS2,
    ToolLoad,
    ToolLoadFit,
    identify_tool_load,
    skew,
)
from ffexp.estimation.wrench_filter import WrenchFilter, WrenchFilterConfig

__all__ = [
    "GRAVITY_BASE_MPS2", "ContactDetector", "ContactDetectorConfig", "ContactEvent", "Estimate",
    "EstimateBatch", "Estimation", "Estimator", "MotionFilter", "MotionFilterConfig",
    "ToolLoad", "ToolLoadFit", "WrenchFilter", "WrenchFilterConfig", "identify_tool_load",
    "skew",
]

