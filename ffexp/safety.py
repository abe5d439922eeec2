"""Every abort condition of a run, checked once per cycle: ``check(...) -> Stop | None``.

Pure: no I/O, no clock. The conditions, in the order they are checked (the
first that holds is the one reported):

1. the F/T sensor's saturation bit on any sample;
2. the force limit ``limits.max_force_n`` on any sample (bias removed once tared);
3. the torque limit ``limits.max_torque_nm`` likewise;
4. stale F/T data: no sample for ``limits.stale_ft_s``;
5. the link: ``limits.link_lost_cycles`` consecutive cycles with an unhealthy
   link, or (once past CONNECT) with the robot not commanding;
6. in APPROACH and ALIGN, the tool speed ``limits.max_speed_mps`` (motion filter);
7. in APPROACH and ALIGN, the workspace box ``limits.workspace_m`` around the
   pose where the approach started (half-widths in that pose's TCF).
"""

from __future__ import annotations

from types import ModuleType

import numpy as np
from numpy.typing import NDArray
from pydantic import Field

from drivers.base.types import F64, NS_PER_S, RobotState
from drivers.config import StrictModel
from ffexp.contracts import Phase, Stop, StopReason
from ffexp.estimation import Estimate


def kernels() -> ModuleType:
    """:mod:`ffexp.controllers.kernels` (its :func:`safety_motion`), imported on first
    use (numba's import is slow)."""
    from ffexp.controllers import kernels as module

    return module


def estimation_kernels() -> ModuleType:
    """:mod:`ffexp.estimation.kernels` (the checks compiled with the estimator's cycle,
    :func:`~ffexp.estimation.kernels.checked_cycle`), imported on first use."""
    from ffexp.estimation import kernels as module

    return module


class Limits(StrictModel):
    """Safety limits; crossing one ends the run in ABORT with a safe stop."""

    max_force_n: float = Field(
        60.0,
        gt=0,
        description="|f| of any F/T sample (bias removed). The funnels' first slip into "
        "the seat reaches ~35 N in the simulator; the Mini45 (SI-145-5) reads 145/290 N.",
    )
    max_torque_nm: float = Field(3.0, gt=0, description="|t| of any raw F/T sample.")
    max_speed_mps: float = Field(0.25, gt=0, description="Tool speed (motion filter).")
    workspace_m: tuple[float, float, float] = Field(
        (0.05, 0.15, 0.35), description="Half-widths of the box around the start pose (TCF)."
    )
    stale_ft_s: float = Field(0.05, gt=0, description="Longest gap without F/T samples.")
    link_lost_cycles: int = Field(
        10, ge=1, description="Consecutive cycles not commanding or with an unhealthy link."
    )


class SafetyMonitor:
    """The abort conditions of :class:`Limits`, with the little state they need.

    Two ways to the same answer: :meth:`check` on an estimate, or the estimator's
    compiled cycle given :attr:`floats` and :attr:`ints` (:meth:`Estimator.update
    <ffexp.estimation.Estimator.update>` with ``checks``), whose answer
    :meth:`stop_for` turns into the :class:`Stop`. Both keep their state (the count of
    bad link cycles, the workspace box's origin) in those rows.
    """

    def __init__(self, limits: Limits, rows: tuple[F64, NDArray[np.int64]] | None = None
                 ) -> None:
        """``rows``: where to keep :attr:`floats` and :attr:`ints` (an estimator's
        :meth:`~ffexp.estimation.Estimator.check_rows`, for its compiled checks); ``None``:
        arrays of its own."""
        self.limits = limits
        self._workspace: list[float] = np.asarray(limits.workspace_m, dtype=np.float64).tolist()
        # the limits as plain floats, and what the compiled motion check takes
        self._max_force_n, self._max_torque_nm = limits.max_force_n, limits.max_torque_nm
        self._max_speed_mps = limits.max_speed_mps
        self._stale_ns = limits.stale_ft_s * NS_PER_S
        self._kernels = kernels()
        ek = self._ek = estimation_kernels()
        if rows is None:
            rows = np.zeros(ek.SF_SIZE), np.zeros(ek.SI_SIZE, dtype=np.int64)
        self.floats = sf = rows[0]
        """The limits, the box's origin and the motion check's outputs
        (:mod:`ffexp.estimation.kernels`' ``SF_*``)."""
        self.ints = si = rows[1]
        """The count of bad link cycles, the limit on it, whether the box has its origin
        (``SI_*``)."""
        if sf.shape != (ek.SF_SIZE,) or si.shape != (ek.SI_SIZE,):
            raise ValueError("a safety monitor's rows are SF_SIZE floats and SI_SIZE ints")
        sf[:] = 0.0
        si[:] = 0
        sf[ek.SF_FORCE], sf[ek.SF_TORQUE] = self._max_force_n, self._max_torque_nm
        sf[ek.SF_SPEED], sf[ek.SF_STALE_NS] = self._max_speed_mps, self._stale_ns
        self._widths = sf[ek.SF_WIDTHS:ek.SF_WIDTHS + 3]
        self._widths[:] = self._workspace
        self._origin_rows = sf[ek.SF_ORIGIN:ek.SF_ORIGIN + 16].reshape(4, 4)  # a view
        self._origin_rows[:] = np.eye(4)  # no origin yet: the box is not checked
        self._motion = sf[ek.SF_MOTION:ek.SF_MOTION + 4]  # speed, offset
        si[ek.SI_LINK_LOST] = limits.link_lost_cycles
        self._origin: F64 | None = None
        self._box: tuple[F64, F64] | None = None  # the origin's R^T and position (views)

    @property
    def _bad_link_cycles(self) -> int:
        return int(self.ints[self._ek.SI_BAD_LINK])

    def set_origin(self, pose: F64) -> None:
        """The pose the workspace box is centred on (where the approach starts)."""
        o = self._origin = pose.copy()
        self._box = (o[:3, :3].T, o[:3, 3])  # views of the copy
        self._origin_rows[:] = o
        self.ints[self._ek.SI_HAS_ORIGIN] = 1

    def stop_for(self, code: int, t_ns: int, state: RobotState, est: Estimate) -> Stop | None:
        """The :class:`Stop` of the compiled checks' answer ``code`` (their
        ``STOP_*``; ``SAFE``: ``None``), said as :meth:`check` says it."""
        k = self._ek
        if code == k.SAFE:
            return None
        if code == k.STOP_SATURATED:
            return Stop(StopReason.FT_SATURATED, "F/T sensor saturated")
        if code == k.STOP_FORCE:
            return self._force_stop(est)
        if code == k.STOP_TORQUE:
            return self._torque_stop(est)
        if code == k.STOP_STALE:
            return self._stale_stop(t_ns, est)
        if code == k.STOP_LINK:
            return self._link_stop(state)
        if code == k.STOP_SPEED:
            return self._speed_stop()
        return self._workspace_stop(state.tcp_pose_m)

    def _force_stop(self, est: Estimate) -> Stop:
        return Stop(
            StopReason.FORCE_LIMIT,
            f"force limit: |f| = {est.peak_force_n:.1f} N > {self.limits.max_force_n} N",
        )

    def _torque_stop(self, est: Estimate) -> Stop:
        return Stop(
            StopReason.TORQUE_LIMIT,
            f"torque limit: |t| = {est.peak_torque_nm:.2f} N m > {self.limits.max_torque_nm} N m",
        )

    @staticmethod
    def _stale_stop(t_ns: int, est: Estimate) -> Stop:
        last = est.last_sample_ns
        since_ns = t_ns - (last if last is not None else 0)
        return Stop(
            StopReason.FT_STALE,
            f"stale F/T data: no sample for {since_ns / NS_PER_S * 1e3:.0f} ms",
        )

    def _link_stop(self, state: RobotState) -> Stop:
        link = state.link
        return Stop(
            StopReason.LINK_BAD,
            f"link lost: {'' if link.commanding else 'not commanding, '}"
            f"{'healthy' if link.healthy else 'unhealthy'} for {self._bad_link_cycles} cycles",
        )

    def _speed_stop(self) -> Stop:
        speed = float(self._motion[0])
        return Stop(
            StopReason.SPEED_LIMIT,
            f"speed limit: {speed:.3f} m/s > {self.limits.max_speed_mps} m/s",
        )

    def check(self, t_ns: int, phase: Phase, state: RobotState, est: Estimate) -> Stop | None:
        """The first condition that holds this cycle, or ``None``."""
        if est.n_samples:
            if est.saturated:
                return Stop(StopReason.FT_SATURATED, "F/T sensor saturated")
            if est.peak_force_n > self._max_force_n:
                return self._force_stop(est)
            if est.peak_torque_nm > self._max_torque_nm:
                return self._torque_stop(est)
        last = est.last_sample_ns
        since_ns = t_ns - (last if last is not None else 0)
        if since_ns > self._stale_ns:
            return self._stale_stop(t_ns, est)
        link = state.link
        bad = not link.healthy or (phase != Phase.CONNECT and not link.commanding)
        ints, i_bad = self.ints, self._ek.SI_BAD_LINK
        ints[i_bad] = ints[i_bad] + 1 if bad else 0
        if ints[i_bad] >= self.limits.link_lost_cycles:
            return self._link_stop(state)
        if phase is Phase.APPROACH or phase is Phase.ALIGN:
            # speed and workspace box compiled (the same sums as np.linalg.norm's dot
            # product and numpy's offset R^T (p - o); a workspace stop says numpy's)
            k = self._kernels
            origin = self._origin
            crossed = k.safety_motion(est.twist_tcf, self._max_speed_mps, state.tcp_pose_m,
                                      self._origin_rows, self._widths, origin is not None,
                                      self._motion)
            if crossed == k.MOTION_SPEED:
                return self._speed_stop()
            if crossed == k.MOTION_WORKSPACE:
                return self._workspace_stop(state.tcp_pose_m)
        return None

    def _workspace_stop(self, pose: F64) -> Stop | None:
        """The workspace condition decided on the offset as numpy makes it."""
        assert self._box is not None
        rt, p = self._box
        offset = rt @ (pose[:3, 3] - p)
        if any(abs(v) > w for v, w in zip(offset.tolist(), self._workspace, strict=True)):
            return Stop(
                StopReason.WORKSPACE_LIMIT,
                f"workspace limit: offset {np.round(offset, 3).tolist()} m",
            )
        return None
