"""The estimator for N runs at once (a single run is a batch of one). No I/O."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from drivers.base.types import F64, FtSamples, RobotState
from ffexp.estimation.config import Estimate, Estimation
from ffexp.estimation.contact import ContactDetector, ContactEvent, contact_settings
from ffexp.estimation.motion_filter import MotionFilter, kernels
from ffexp.estimation.tool_load import skew
from ffexp.estimation.wrench_filter import wrench_noise

I64 = NDArray[np.int64]
_NONE_NS = np.iinfo(np.int64).min  # kernels.NONE_NS
_KINDS = (None, "made", "broken")


class SafetyRows(Protocol):
    """What :meth:`Estimator.update` checks an estimate against in its compiled call:
    the safety monitor's rows (:mod:`ffexp.estimation.kernels`' ``SF_*`` and ``SI_*``)."""

    floats: F64
    ints: I64


@dataclass
class EstimateBatch:
    """Every run's outputs of a cycle, one row per run (arrays the estimator reuses:
    copy what is kept). Columns: :mod:`ffexp.estimation.kernels`' ``OF_*`` and ``OI_*``
    (wrench, its 1-sigma, bias, twist in the TCF, ``f_z``, the peaks; the sample count,
    contact, event (kind, start, previous start), saturation, tare, newest sample)."""

    floats: F64
    ints: I64


class RowEstimate(Estimate):
    """A single run's :class:`Estimate` read from the estimator's output rows: its
    arrays are views of them, its scalars read from them when asked (but ``in_contact``
    and ``event``, which the estimator sets each cycle)."""

    def __init__(self, floats: F64, ints: I64) -> None:  # no dataclass __init__
        k = kernels()
        self.floats, self.ints = floats, ints
        self._f, self._i = floats, ints
        self.wrench = floats[k.OF_WRENCH:k.OF_WRENCH + 6]
        self.wrench_std = floats[k.OF_STD:k.OF_STD + 6]
        self.bias = floats[k.OF_BIAS:k.OF_BIAS + 6]
        self.twist_tcf = floats[k.OF_TWIST:k.OF_TWIST + 6]
        self.in_contact = False
        self.event = None

    @property
    def f_z(self) -> float:  # type: ignore[override]
        return float(self._f[24])  # kernels.OF_FZ

    @property
    def peak_force_n(self) -> float:  # type: ignore[override]
        return float(self._f[25])  # kernels.OF_PEAK_F

    @property
    def peak_torque_nm(self) -> float:  # type: ignore[override]
        return float(self._f[26])  # kernels.OF_PEAK_T

    @property
    def n_samples(self) -> int:  # type: ignore[override]
        return int(self._i[0])  # kernels.OI_N

    @property
    def saturated(self) -> bool:  # type: ignore[override]
        return bool(self._i[5] == 1)  # kernels.OI_SATURATED

    @property
    def tared(self) -> bool:  # type: ignore[override]
        return bool(self._i[6] == 1)  # kernels.OI_TARED

    @property
    def tared_now(self) -> bool:  # type: ignore[override]
        return bool(self._i[7] == 1)  # kernels.OI_TARED_NOW

    @property
    def tare_samples(self) -> int:  # type: ignore[override]
        return int(self._i[8])  # kernels.OI_TARE_SAMPLES

    @property
    def last_sample_ns(self) -> int | None:  # type: ignore[override]
        last = int(self._i[9])  # kernels.OI_LAST
        return None if last == _NONE_NS else last


class Estimator:
    """Compensation, tare, wrench and motion filters, contact detection, for ``N`` runs.

    Args:
        config: the protocol's ``[estimation]``, or one per run (they may differ in
            everything but the motion filter's settings, which the runs share).
        cycle_s: the robot's control cycle (shared).
        tare_s: sensor time the tare needs (the protocol's ``run.tare_s``), or one per run.

    :meth:`update` steps a single run (``N = 1``) with the loop's inputs and returns its
    :class:`Estimate`; :meth:`update_batch` steps every run from arrays with the run
    first. Both go through one compiled cycle (:func:`kernels.estimator_cycle`).
    """

    def __init__(self, config: Estimation | Sequence[Estimation], cycle_s: float,
                 tare_s: float | Sequence[float]) -> None:
        configs = [config] if isinstance(config, Estimation) else list(config)
        runs = len(configs)
        tares = [tare_s] * runs if isinstance(tare_s, (int, float)) else list(tare_s)
        if runs < 1 or len(tares) != runs:
            raise ValueError(f"{runs} estimation settings and {len(tares)} tare times: "
                             "one of each per run")
        if any(c.motion != configs[0].motion for c in configs):
            raise ValueError("the runs of a batch share the motion filter's settings")
        self.config = configs[0]
        self.configs = configs
        self.runs = runs
        self.cycle_s = cycle_s
        self.tare_ns = round(tares[0] * 1e9)
        self._k = k = kernels()
        # a single run's state packed in two rows (kernels.P_*, Q_*): its cycle is one
        # call of few arguments; a batch keeps an array each
        single = runs == 1
        self._fb = fb = np.zeros(k.P_SIZE)
        self._ib = ib = np.zeros(k.Q_SIZE, dtype=np.int64)
        self.motion_filter = MotionFilter(
            configs[0].motion, cycle_s, runs,
            fb[k.P_MOTION:k.P_MOTION + k.MOTION_SIZE] if single else None)
        self.detector = ContactDetector(configs[0].contact)
        self.detectors = [self.detector, *(ContactDetector(c.contact) for c in configs[1:])]
        cfg = fb[k.P_CFG:k.P_FS].reshape(1, -1) if single else np.zeros((runs, k.CF_SIZE))
        fs = fb[k.P_FS:k.P_OF].reshape(1, -1) if single else np.zeros((runs, k.FS_SIZE))
        fs[:, k.WF_P_FF:k.WF_P_FF + 6] = 100.0  # the wrench filter's prior before the tare
        fs[:, k.WF_P_BB:k.WF_P_BB + 6] = 100.0
        ist = (ib[k.Q_IST:k.Q_OI].reshape(1, -1) if single
               else np.zeros((runs, k.IS_SIZE), dtype=np.int64))
        ist[:, k.IS_CD + k.CD_PENDING] = ist[:, k.IS_CD + k.CD_SINCE] = k.NONE_NS
        ist[:, k.ST_FIRST] = ist[:, k.ST_LAST] = k.NONE_NS
        ist[:, k.ST_TARE_NS] = [round(t * 1e9) for t in tares]
        ist[:, k.IS_COMMANDING] = 1
        for i, c in enumerate(configs):
            cfg[i, k.CF_WQ:k.CF_CC] = wrench_noise(c.wrench, cycle_s)
            cfg[i, k.CF_CC:k.CF_LD] = contact_settings(c.contact)
            ld = cfg[i, k.CF_LD:]
            tl = c.tool_load
            ld[k.LD_MASS] = tl.mass_kg
            ld[k.LD_COMPENSATE] = tl.mass_kg > 0.0
            ld[k.LD_INERTIAL] = c.inertial_compensation
            ld[k.LD_GRAVITY:k.LD_GRAVITY + 3] = tl.gravity_base()
            ld[k.LD_SKEW:k.LD_SKEW + 9] = skew(np.asarray(tl.com_m, dtype=np.float64)).ravel()
        self._cfg, self._fs, self._ist = cfg, fs, ist
        self._of = (fb[k.P_OF:k.P_MOTION].reshape(1, -1) if single
                    else np.zeros((runs, k.OF_SIZE)))
        self._oi = (ib[k.Q_OI:k.Q_MJU].reshape(1, -1) if single
                    else np.zeros((runs, k.OI_SIZE), dtype=np.int64))
        ib[k.Q_MJU:k.Q_SI] = self.motion_filter._mju
        # the safety monitor's rows a single run's checks use (check_rows)
        self._sf, self._si = fb[k.P_SF:k.P_SIZE], ib[k.Q_SI:k.Q_GAIN]
        self.batch = EstimateBatch(self._of, self._oi)
        # a single run's outputs: views of the first row, made once (Estimate's arrays
        # are reused between cycles)
        self.out: Estimate = RowEstimate(self._of[0], self._oi[0])
        self._oi0 = self._oi[0]
        self._none_ns = k.NONE_NS
        # once the motion filter's gains repeat, their cycle as one table (six rows a
        # gain) that update's compiled call steps through itself (its place: ib[Q_GAIN])
        self._gains: F64 | None = None
        self.safety_code = 0
        """Which of the safety checks held first in the last checked :meth:`update`."""

    def update_batch(self, poses: F64, wrench: F64, time_ns: I64, status: NDArray[np.uint32],
                     offsets: I64, commanding: NDArray[np.bool_], t_ns: I64,
                     t0_ns: I64) -> EstimateBatch:
        """One cycle of every run: ``poses`` (N, 4, 4) the tool poses; the runs' F/T
        samples one after the other (``wrench`` (S, 6), ``time_ns``, ``status`` (S,)), run
        ``i``'s from ``offsets[i]`` to ``offsets[i + 1]`` (none: equal); ``commanding``,
        ``t_ns`` (the cycle's run time) and ``t0_ns`` (the robot time of the run's start)
        per run. Returns the runs' outputs (:class:`EstimateBatch`); the contact events go
        to each run's :attr:`detectors` entry too."""
        k = self._k
        ist = self._ist
        ist[:, k.IS_COMMANDING] = commanding
        ist[:, k.IS_T_NS] = t_ns
        ist[:, k.IS_T0_NS] = t0_ns
        self._cycle(poses, wrench, time_ns, status, offsets)
        ev = self._oi[:, k.OI_EVENT]
        if ev.any():
            for i in np.flatnonzero(ev).tolist():
                self._event(i, self._oi[i].tolist())
        return self.batch

    def _cycle(self, poses: F64, wrench: F64, time_ns: I64, status: NDArray[np.uint32],
               offsets: I64) -> None:
        mf = self.motion_filter
        started = mf._started
        mf._started = True
        self._k.estimator_cycle(
            self._cfg, self._fs, self._ist, mf._x, mf._rot, mf._theta, started,
            mf.next_gain(), mf._f1_t, mf._mju, wrench, time_ns, status, offsets, poses,
            self._of, self._oi)

    def _event(self, i: int, ints: list[int]) -> ContactEvent:
        k = self._k
        kind, start, since = ints[k.OI_EVENT:k.OI_EVENT + 3]
        event = ContactEvent(kind=_KINDS[kind], time_ns=start,  # type: ignore[arg-type]
                             previous_s=(start - since) * 1e-9)
        det = self.detectors[i]
        det.events.append(event)
        det.in_contact = kind == 1
        return event

    def check_rows(self) -> tuple[F64, I64]:
        """The rows a :class:`~ffexp.safety.SafetyMonitor` keeps its limits and state in
        for :meth:`update` to check a single run's estimate in its compiled call
        (``SafetyMonitor(limits, rows=estimator.check_rows())``)."""
        return self._sf, self._si

    def update(self, state: RobotState, ft: FtSamples, t_ns: int, t0_ns: int,
               checks: SafetyRows | None = None, phase: int = 0) -> Estimate:
        """One cycle of a single run (the batch of one). ``t_ns`` is the run time of the
        cycle, ``t0_ns`` the robot time of the run's start (sample times are on the
        robot's clock).

        With ``checks`` (a :class:`~ffexp.safety.SafetyMonitor` on :meth:`check_rows`),
        the monitor's checks on this estimate in the same compiled call
        (:func:`kernels.checked_cycle`; ``phase`` the task's phase before the cycle):
        which one held first is left in :attr:`safety_code` (``kernels.SAFE`` for
        none).

        Once the motion filter's gain repeats (:attr:`MotionFilter.gain_period
        <ffexp.estimation.motion_filter.MotionFilter.gain_period>`), its cycle of gains
        is stepped through by the compiled call (the same gains in the same order; the
        filter's own place in its cycle is then no longer moved: this estimator steps
        it)."""
        if self.runs != 1:
            raise ValueError(f"update steps a single run; this estimator has {self.runs}: "
                             "update_batch")
        mf = self.motion_filter
        started = mf._started
        mf._started = True
        link = state.link
        if checks is None:
            check = False
        elif checks.floats is self._sf:
            check = True
        else:
            raise ValueError("update checks with a safety monitor on this estimator's "
                             "check_rows()")
        table = self._gains
        r = self._k.checked_cycle(
            self._fb, self._ib, mf.next_gain() if table is None else table, ft.wrench,
            ft.time_ns, ft.status, state.tcp_pose_m, started, link.commanding, t_ns, t0_ns,
            link.healthy, phase == 0, phase == 1 or phase == 2, check)
        if table is None and mf.gain_period:  # the gains repeat: from the next cycle, the table
            self._gains, self._ib[self._k.Q_GAIN] = mf.gain_table()
        self.safety_code = r & 15  # kernels.R_CHECK
        out = self.out  # views of the outputs: the scalars read from them when asked
        out.in_contact = r & 16 != 0  # kernels.R_IN_CONTACT
        out.event = self._event(0, self._oi0.tolist()) if r & 32 else None  # R_EVENT
        return out
