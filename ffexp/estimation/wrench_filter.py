"""The wrench Kalman filter (filterpy): per TCF axis the true wrench and the sensor bias.

A Kalman filter over 12 states (six 2-state filters side by side), per TCF axis the
true wrench ``f`` (random walk, fast) and the sensor bias ``b`` (random
walk, slow: the Mini45 drifts 0.1-0.4 N over minutes), measured as
``z = f + b + noise``. The bias is observable only while the wrench is
known to be zero, so :meth:`WrenchFilter.tare` feeds N samples taken in
free space with a pseudo-measurement ``f = 0``; afterwards the bias moves
only as slowly as its drift allows and the fast state follows the contact.
All F/T samples that arrive in one controller cycle update the filter once,
with their mean and the covariance divided by their number. No I/O.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
from pydantic import Field, model_validator

from drivers.base.types import F64
from drivers.config import StrictModel, Vec6


class WrenchFilterConfig(StrictModel):
    """Noise model of the wrench filter (per TCF axis, SI units).

    Defaults: white noise from the Mini45 fact sheet (1 sigma per sample at
    ~1-2 kHz: Fx 0.02, Fy 0.019, Fz 0.05 N; torques from the 1/752 N m
    resolution), drift 0.17-0.36 N over 10 min read as a random walk of about
    0.01 N/sqrt(s), and a wrench that may change by ~20 N/sqrt(s) in contact.
    """

    noise_std: Vec6 = (0.02, 0.02, 0.05, 0.002, 0.002, 0.001)
    wrench_walk_std: Vec6 = Field(
        (20.0, 20.0, 20.0, 2.0, 2.0, 2.0), description="Random walk of the wrench [unit/sqrt(s)]."
    )
    bias_walk_std: Vec6 = Field(
        (0.01, 0.01, 0.01, 0.0005, 0.0005, 0.0005),
        description="Random walk of the bias [unit/sqrt(s)].",
    )

    @model_validator(mode="after")
    def _positive(self) -> WrenchFilterConfig:
        for name in ("noise_std", "wrench_walk_std", "bias_walk_std"):
            if any(v <= 0.0 for v in getattr(self, name)):
                raise ValueError(f"{name}: every entry must be > 0")
        return self


class WrenchFilter:
    """Kalman filter of the measured wrench with a per-axis bias state.

    The model is separable per axis (``F = I``, ``H = [I I]``, diagonal
    ``Q`` and ``R``, and a tare that leaves ``P`` block-diagonal), so the
    12-state filter is run as six 2-state filters side by side on arrays of
    six: the same equations as a :class:`filterpy.kalman.KalmanFilter` over
    the 12 states (``tests/test_speed_estimation.py`` checks that), at a
    fraction of its per-cycle cost (no 12x12 products or inverse).
    """

    def __init__(self, config: WrenchFilterConfig) -> None:
        self.config = config
        r = np.square(np.asarray(config.noise_std, dtype=np.float64))
        self._r_arr = r
        # per axis as floats (the elementwise arithmetic of arrays of six, done on the
        # floats: the same IEEE operations, without a numpy call per operation)
        self._r: list[float] = r.tolist()
        self._q_f: list[float] = np.square(
            np.asarray(config.wrench_walk_std, dtype=np.float64)).tolist()
        self._q_b: list[float] = np.square(
            np.asarray(config.bias_walk_std, dtype=np.float64)).tolist()
        self._q_dt = math.nan  # the dt_s of _qdt_f, _qdt_b
        self._qdt_f: list[float] = []
        self._qdt_b: list[float] = []
        self._x_f = [0.0] * 6
        self._x_b = [0.0] * 6
        # covariance per axis: P = [[p_ff, p_fb], [p_fb, p_bb]]
        self._p_ff = [100.0] * 6
        self._p_fb = [0.0] * 6
        self._p_bb = [100.0] * 6
        self.tared = False

    def tare(self, samples: F64) -> None:
        """Estimate the bias from samples (N, 6) taken in free space (wrench = 0).

        A bias-only Kalman filter (``z = b + noise``, prior ``b = 0`` with
        variance 100, no process noise) over the samples, in its closed form
        (information filter: ``1/P = 1/100 + N/r``, ``b = P sum(z) / r``);
        its estimate and covariance become the bias part of the filter, and
        the wrench state restarts at zero with the noise's uncertainty.
        """
        samples = np.asarray(samples, dtype=np.float64).reshape(-1, 6)
        n = samples.shape[0]
        if n == 0:
            raise ValueError("tare needs at least one sample")
        r = self._r_arr
        p_b = 1.0 / (1.0 / 100.0 + n / r)
        self._x_b = (p_b * samples.sum(axis=0) / r).tolist()
        self._x_f = [0.0] * 6
        self._p_ff = list(self._r)
        self._p_fb = [0.0] * 6
        self._p_bb = p_b.tolist()
        self.tared = True

    def update(self, samples: F64, dt_s: float) -> None:
        """Predict over ``dt_s`` and update with the mean of this cycle's samples.

        With no samples the filter only predicts (its covariance grows).
        """
        self.update_rows(np.asarray(samples, dtype=np.float64).reshape(-1, 6).tolist(), dt_s)

    def update_rows(self, rows: list[list[float]], dt_s: float) -> None:
        """:meth:`update` with the samples as rows of six floats."""
        if dt_s != self._q_dt:  # the process noise over dt_s (q dt), kept for the next cycle
            self._q_dt = dt_s
            self._qdt_f = [q * dt_s for q in self._q_f]
            self._qdt_b = [q * dt_s for q in self._q_b]
        p_ff = self._p_ff = [p + q for p, q in zip(self._p_ff, self._qdt_f, strict=True)]
        p_bb = self._p_bb = [p + q for p, q in zip(self._p_bb, self._qdt_b, strict=True)]
        p_fb, x_f, x_b = self._p_fb, self._x_f, self._x_b
        n = len(rows)
        if not n:
            return
        if n > 1:  # the mean, summed row after row as numpy's reduce over axis 0 does
            a0, a1, a2, a3, a4, a5 = rows[0]
            for r0, r1, r2, r3, r4, r5 in itertools.islice(rows, 1, None):
                a0 += r0
                a1 += r1
                a2 += r2
                a3 += r3
                a4 += r4
                a5 += r5
            z = [a0 / n, a1 / n, a2 / n, a3 / n, a4 / n, a5 / n]
        else:
            z = rows[0]
        r = self._r
        for k in range(6):
            ff, fb, bb = p_ff[k], p_fb[k], p_bb[k]
            s = ff + 2.0 * fb + bb + r[k] / n
            k_f = (ff + fb) / s
            k_b = (fb + bb) / s
            y = z[k] - x_f[k] - x_b[k]
            x_f[k] += k_f * y
            x_b[k] += k_b * y
            # P - K S K^T, per axis
            p_ff[k] = ff - k_f * k_f * s
            p_fb[k] = fb - k_f * k_b * s
            p_bb[k] = bb - k_b * k_b * s

    @property
    def wrench(self) -> F64:
        """Filtered wrench (bias removed), TCF."""
        return np.array(self._x_f)

    @property
    def bias(self) -> F64:
        """Estimated sensor bias, TCF."""
        return np.array(self._x_b)

    @property
    def wrench_std(self) -> F64:
        """1-sigma uncertainty of :attr:`wrench`."""
        return np.array([math.sqrt(v) for v in self._p_ff])

    @property
    def wrench_list(self) -> list[float]:
        """:attr:`wrench` as floats (the filter's own list: do not modify)."""
        return self._x_f

    @property
    def bias_list(self) -> list[float]:
        """:attr:`bias` as floats (the filter's own list: do not modify)."""
        return self._x_b


