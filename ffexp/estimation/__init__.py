"""The estimator of the experiment loop: everything done to the sensor signal per cycle.

Its parts, one module each (pure: no I/O): :mod:`ffexp.estimation.wrench_filter`
and :mod:`ffexp.estimation.motion_filter` (Kalman filters, filterpy),
:mod:`ffexp.estimation.tool_load` (the tool's weight and inertia and their
identification) and :mod:`ffexp.estimation.contact` (the contact detector).

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

import math
from dataclasses import dataclass, field

import numpy as np
from pydantic import Field

from drivers.base.types import F64, FtSamples, FtStatus, RobotState
from drivers.config import StrictModel
from ffexp.estimation.contact import ContactDetector, ContactDetectorConfig, ContactEvent
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
    "Estimation", "Estimator", "MotionFilter", "MotionFilterConfig", "ToolLoad", "ToolLoadFit",
    "WrenchFilter", "WrenchFilterConfig", "identify_tool_load", "peaks", "skew",
]


class Estimation(StrictModel):
    """Filters, tool load and contact detection (the protocol's ``[estimation]``)."""

    wrench: WrenchFilterConfig = WrenchFilterConfig()
    motion: MotionFilterConfig = MotionFilterConfig()
    tool_load: ToolLoad = ToolLoad()
    inertial_compensation: bool = Field(
        True,
        description="Also remove the tool's inertia (mass x acceleration from the motion "
        "filter) from the reading; needs tool_load.mass_kg.",
    )
    contact: ContactDetectorConfig = ContactDetectorConfig()


@dataclass
class Estimate:
    """What the estimator says about one cycle (arrays are reused between cycles)."""

    wrench: F64 = field(default_factory=lambda: np.zeros(6))
    """Filtered contact wrench (environment on tool), bias and tool load removed, TCF."""
    wrench_std: F64 = field(default_factory=lambda: np.zeros(6))
    bias: F64 = field(default_factory=lambda: np.zeros(6))
    twist_tcf: F64 = field(default_factory=lambda: np.zeros(6))
    f_z: float = 0.0
    """Contact force along the approach axis, ``-wrench[2]`` [N]."""
    n_samples: int = 0
    in_contact: bool = False
    event: ContactEvent | None = None
    """Contact made or broken, confirmed this cycle."""
    tared: bool = False
    tared_now: bool = False
    """The tare happened this cycle."""
    tare_samples: int = 0
    peak_force_n: float = 0.0
    """Largest |f| of this cycle's samples (compensated, bias removed once tared)."""
    peak_torque_nm: float = 0.0
    saturated: bool = False
    """A sample of this cycle carried the sensor's saturation bit."""
    last_sample_ns: int | None = None
    """Time of the newest sample so far, on the robot's clock [ns]."""


_SATURATION = int(FtStatus.SATURATION)


def _peak(squares: list[float]) -> float:
    """``sqrt(max(squares))`` with numpy's rule for NaN (a NaN anywhere is the maximum)."""
    total = sum(squares)  # NaN exactly when one is (squares are >= 0: no inf - inf)
    if total != total:
        return math.nan
    return math.sqrt(max(squares))


def peaks(rows: list[list[float]]) -> tuple[float, float]:
    """The largest |f| and |t| of wrench rows: on floats, the bits of numpy's
    ``sqrt(max((w[:, :3]**2).sum(axis=1)))`` (its sum of three adds left to right)."""
    return (_peak([r[0] * r[0] + r[1] * r[1] + r[2] * r[2] for r in rows]),
            _peak([r[3] * r[3] + r[4] * r[4] + r[5] * r[5] for r in rows]))


def _unbiased_peaks(rows: list[list[float]], bias: list[float]) -> tuple[float, float]:
    """:func:`peaks` of the rows with ``bias`` subtracted, in one pass (the same
    subtractions and sums, without the rows of differences)."""
    b0, b1, b2, b3, b4, b5 = bias
    f2: list[float] = []
    t2: list[float] = []
    for w0, w1, w2, w3, w4, w5 in rows:
        s0, s1, s2 = w0 - b0, w1 - b1, w2 - b2
        s3, s4, s5 = w3 - b3, w4 - b4, w5 - b5
        f2.append(s0 * s0 + s1 * s1 + s2 * s2)
        t2.append(s3 * s3 + s4 * s4 + s5 * s5)
    return _peak(f2), _peak(t2)


class Estimator:
    """Compensation, tare, wrench and motion filters, contact detection.

    Args:
        config: the protocol's ``[estimation]``.
        cycle_s: the robot's control cycle.
        tare_s: sensor time the tare needs (the protocol's ``run.tare_s``).
    """

    def __init__(self, config: Estimation, cycle_s: float, tare_s: float) -> None:
        self.config = config
        self.cycle_s = cycle_s
        self.tare_ns = round(tare_s * 1e9)
        self.wrench_filter = WrenchFilter(config.wrench)
        self.motion_filter = MotionFilter(config.motion, cycle_s)
        self.detector = ContactDetector(config.contact)
        self._tare: list[F64] = []
        self._tare_first_ns: int | None = None
        self._compensate = config.tool_load.mass_kg > 0.0
        self._mass_kg = config.tool_load.mass_kg
        self._com_skew = skew(np.asarray(config.tool_load.com_m, dtype=np.float64))
        self._load = np.zeros(6)
        self._gravity = config.tool_load.gravity_base()
        self.out = Estimate()

    def _tool_load(self, r_base_sensor: F64, accel_base: F64 | None) -> F64:
        """:meth:`ToolLoad.wrench <ffexp.estimation.ToolLoad.wrench>` into a reused array."""
        g = self._gravity if accel_base is None else self._gravity - accel_base
        f = self._mass_kg * (g @ r_base_sensor)
        load = self._load
        load[:3] = f
        np.matmul(self._com_skew, f, out=load[3:])  # com x f
        return load

    def update(self, state: RobotState, ft: FtSamples, t_ns: int, t0_ns: int) -> Estimate:
        """One cycle. ``t_ns`` is the run time of the cycle, ``t0_ns`` the robot time of
        the run's start (sample times are on the robot's clock).

        The samples are handled as rows of floats (a cycle holds a handful): the
        compensation, the peaks and the filter's update are elementwise, the same
        IEEE operations in the same order as on the arrays.
        """
        out = self.out
        cfg = self.config
        wf, mf = self.wrench_filter, self.motion_filter
        pose = state.tcp_pose_m
        n = len(ft)
        raw: list[list[float]] = ft.wrench.tolist() if n else []
        comp = raw
        if self._compensate and n:
            accel = mf.accel_linear_view if cfg.inertial_compensation else None
            l0, l1, l2, l3, l4, l5 = self._tool_load(pose[:3, :3], accel).tolist()
            comp = [[w0 - l0, w1 - l1, w2 - l2, w3 - l3, w4 - l4, w5 - l5]
                    for w0, w1, w2, w3, w4, w5 in raw]
        out.n_samples = n
        out.event = None
        out.tared_now = False
        if n:
            out.last_sample_ns = int(ft.time_ns[-1]) - t0_ns
            out.saturated = any(s & _SATURATION for s in ft.status.tolist())
            if wf.tared:
                out.peak_force_n, out.peak_torque_nm = _unbiased_peaks(comp, wf.bias_list)
            else:
                out.peak_force_n, out.peak_torque_nm = peaks(raw)
        else:
            out.saturated = False
            out.peak_force_n = out.peak_torque_nm = 0.0
        mf.update(pose)
        out.twist_tcf = mf.twist_tcf(pose)
        if not wf.tared:
            if n:
                self._tare.append(np.array(comp))
                if self._tare_first_ns is None:
                    self._tare_first_ns = int(ft.time_ns[0]) - t0_ns
            self._try_tare(state)
        else:
            wf.update_rows(comp, self.cycle_s)
        out.wrench = wf.wrench
        if wf.tared and not out.tared_now:
            out.event = self.detector.update(t_ns, out.wrench)
        out.in_contact = self.detector.in_contact
        out.f_z = -wf.wrench_list[2]
        out.wrench_std = wf.wrench_std
        out.bias = wf.bias
        out.tared = wf.tared
        return out

    def _try_tare(self, state: RobotState) -> None:
        out = self.out
        first, last = self._tare_first_ns, out.last_sample_ns
        if first is None or last is None or not state.link.commanding:
            return
        # the samples cover [first, last] plus one sample period
        count = sum(len(x) for x in self._tare)
        period_ns = (last - first) / max(count - 1, 1)
        if last - first + period_ns < self.tare_ns:
            return
        self.wrench_filter.tare(np.concatenate(self._tare))
        self._tare = []
        out.tare_samples = count
        out.tared_now = True
