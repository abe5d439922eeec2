"""The tool-motion Kalman filter (filterpy): constant acceleration per axis.

Position, velocity and acceleration per axis over the tool's translation and its
accumulated rotation vector, both in the base frame, measured from the pose once
per cycle. No I/O.
"""

from __future__ import annotations

from types import ModuleType

import numpy as np
from filterpy.common import Q_discrete_white_noise
from pydantic import Field

from drivers.base.types import F64
from drivers.config import StrictModel


class MotionFilterConfig(StrictModel):
    """Constant-acceleration model of the tool motion."""

    position_noise_m: float = Field(1e-5, gt=0)
    rotation_noise_rad: float = Field(1e-4, gt=0)
    accel_walk: float = Field(50.0, gt=0, description="Jerk noise spectral density [m/s^3].")


def kernels() -> ModuleType:
    """:mod:`ffexp.estimation.kernels`, imported on first use (numba's import is slow)."""
    from ffexp.estimation import kernels as module

    return module


#: Cycles :class:`MotionFilter` looks for its covariance to repeat before it stops looking.
_GAIN_WATCH_CYCLES = 2000


class MotionFilter:
    """Velocity and acceleration of the tool from its pose (base frame), for ``runs``
    runs at once (arrays with the run axis first; a single run is a batch of one).

    Six independent constant-acceleration filters (x, y, z and the three
    components of the accumulated rotation vector), run side by side: the
    same equations as one :class:`filterpy.kalman.KalmanFilter` over 18
    states with ``F = I6 (x) F1``, ``H = I6 (x) [1 0 0]`` and filterpy's
    ``Q_discrete_white_noise`` per axis (``tests/test_speed_estimation.py``
    checks that), without its 18x18 products.

    The covariance and the gain do not depend on the measurements, and in
    floating point the covariance's recursion falls into a cycle (at 5 ms:
    after about 100 cycles, of 57 cycles): once the covariance after an update
    equals an earlier one bit for bit, every later covariance and gain is the
    one computed that many cycles before, so they are taken from that cycle
    instead of computed (exact: the same bits as computing them). So the runs of
    a batch, which share the filter's settings and cycle and start together, share
    one gain; each run's state is its own six rows (one array of ``6 N`` rows), its
    last rotation and its rotation vector, stepped by the compiled
    :func:`ffexp.estimation.kernels.motion_step` (the estimator's own, which calls
    MuJoCo's ``mju_mat2Quat`` and ``mju_quat2Vel``), and a run's numbers are those it
    gets alone (``tests/test_estimation.py``).
    """

    def __init__(self, config: MotionFilterConfig, cycle_s: float, runs: int = 1,
                 rows: F64 | None = None) -> None:
        """``rows``: a single run's float row to keep its state in (``x``, ``rot``,
        ``theta``, ``F1^T``: :data:`ffexp.estimation.kernels.MOTION_SIZE` floats), as the
        estimator packs it; ``None``: arrays of its own."""
        if runs < 1:
            raise ValueError(f"a motion filter needs at least one run, not {runs}")
        self.config = config
        self.cycle_s = cycle_s
        self.runs = runs
        self._f1 = np.array([[1.0, cycle_s, 0.5 * cycle_s**2], [0.0, 1.0, cycle_s],
                             [0.0, 0.0, 1.0]])
        if rows is not None and (runs != 1 or rows.shape != (39,)):
            raise ValueError("a motion filter keeps a single run's state in 39 floats")
        self._f1_t = self._f1.T.copy() if rows is None else rows[30:39].reshape(3, 3)
        self._f1_t[...] = self._f1.T
        self._q1 = Q_discrete_white_noise(dim=3, dt=cycle_s, var=config.accel_walk**2 * cycle_s)
        noise = [config.position_noise_m] * 3 + [config.rotation_noise_rad] * 3
        self._r = np.square(np.asarray(noise, dtype=np.float64))
        # per run and axis (run i's six axes are rows 6i to 6i + 5, so that one run's
        # arrays are exactly the single filter's): value, rate, acceleration
        self._x = np.zeros((6 * runs, 3)) if rows is None else rows[0:18].reshape(6, 3)
        self._p = np.tile(np.eye(3) * 1e-2, (6, 1, 1))  # shared by the runs
        # each run's last rotation (once started) and accumulated rotation vector
        self._rot = np.zeros((runs, 3, 3)) if rows is None else rows[18:27].reshape(1, 3, 3)
        self._theta = np.zeros((runs, 3)) if rows is None else rows[27:30].reshape(1, 3)
        self._work = np.zeros(16)
        self._started = False
        # the covariance and gain do not depend on the measurements: once the
        # covariance repeats bit for bit, its later values (and the gains) repeat too
        self._watch: dict[bytes, int] | None = {}  # covariance bytes: cycle seen
        self._watch_cycles = _GAIN_WATCH_CYCLES
        self._history: list[tuple[F64, F64]] = []  # (gain, covariance)
        self._cycle: list[tuple[F64, F64]] = []  # once found: its repeats
        self._at = 0  # the next cycle's place in it
        self._kernels = k = kernels()
        self._mju = k.mujoco_functions()

    def update(self, pose: F64) -> None:
        """One cycle of a single run with its measured 4x4 tool pose (base frame)."""
        self.update_batch(pose[None])

    def update_batch(self, poses: F64) -> None:
        """One cycle of every run, with the runs' measured 4x4 tool poses ``(N, 4, 4)``
        (base frame)."""
        started = self._started
        self._started = True
        self._kernels.motion_batch(self._x, self._rot, self._theta, started, poses,
                                   self.next_gain(), self._f1_t, self._mju, self._work)

    def next_gain(self) -> F64:
        """The gain of the next cycle (6, 3), shared by the runs; the covariance moves on
        to that cycle's (:meth:`update_batch` calls it; a caller that steps the runs'
        states itself, as :class:`~ffexp.estimation.Estimator`, calls it once a cycle)."""
        cycle = self._cycle
        if cycle:  # the covariance repeats: its gain and covariance as computed before
            k, p_next = cycle[self._at]
            self._at = (self._at + 1) % len(cycle)
        else:
            k, p_next = self._gain()
        self._p = p_next
        return k

    def _gain(self) -> tuple[F64, F64]:
        """The gain of this cycle and the covariance after its update, computed; once
        the covariance equals one of an earlier cycle bit for bit, the values from that
        cycle on are kept to be repeated (:attr:`gain_period`).

        Compiled (:func:`ffexp.estimation.kernels.motion_gain`): bit for bit the numpy
        form ``P = F1 P F1^T + Q1``, ``k = P[:, :, 0] / (P[:, 0, 0] + r)``,
        ``P -= k P[0, :]`` (``tests/test_estimation_batch.py``)."""
        k, p = np.empty((6, 3)), np.empty((6, 3, 3))
        self._kernels.motion_gain(self._f1, self._p, self._f1_t, self._q1, self._r, k, p)
        watch = self._watch
        if watch is not None:
            k.flags.writeable = p.flags.writeable = False
            key = p.tobytes()
            first = watch.get(key)
            history = self._history
            if first is not None:  # P_n == P_first: from here on, P and K repeat
                self._cycle = [*history[first + 1:], (k, p)]
                self._at = 0
                self._watch, self._history = None, []
            elif len(history) >= self._watch_cycles:
                self._watch, self._history = None, []  # none found: always compute
            else:
                watch[key] = len(history)
                history.append((k, p))
        return k, p

    @property
    def gain_period(self) -> int:
        """Cycles after which the filter's gain repeats bit for bit (0: not, or not yet)."""
        return len(self._cycle)

    def gain_table(self) -> tuple[F64, int]:
        """Once the gain repeats (:attr:`gain_period`): its cycle of gains as one table,
        six rows a gain (``(6 n, 3)``), and the place of the next cycle's gain in it (a
        caller that steps through the table itself, as the estimator's compiled cycle)."""
        if not self._cycle:
            raise ValueError("the motion filter's gain does not repeat (yet)")
        return np.concatenate([g for g, _ in self._cycle]), self._at

    @property
    def twist_base(self) -> F64:
        """[vx, vy, vz, wx, wy, wz] in the base frame (of the first run)."""
        return self._x[:6, 1].copy()

    @property
    def accel_base(self) -> F64:
        """Linear and angular acceleration in the base frame (of the first run)."""
        return self._x[:6, 2].copy()

    @property
    def accel_linear_view(self) -> F64:
        """The linear part of :attr:`accel_base`, a view of the state (do not modify)."""
        return self._x[:3, 2]

    @property
    def accel_linear_views(self) -> F64:
        """Every run's :attr:`accel_linear_view`, ``(N, 3)`` (a view: do not modify)."""
        return self._x[:, 2].reshape(self.runs, 6)[:, :3]

    def twist_tcf(self, pose: F64) -> F64:
        """The twist expressed in the tool frame of ``pose`` (a single run: the first)."""
        out = np.empty(6)
        self._kernels.twist_tcf(self._x, pose, out)
        return out

    def twist_tcf_batch(self, poses: F64) -> F64:
        """Each run's twist in the tool frame of its pose, ``(N, 6)``."""
        out = np.empty((self.runs, 6))
        tw = self._kernels.twist_tcf
        for i in range(self.runs):
            tw(self._x[6 * i:6 * i + 6], poses[i], out[i])
        return out
