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


def wrench_noise(config: WrenchFilterConfig, dt_s: float) -> F64:
    """One run's noise for :mod:`ffexp.estimation.kernels`: ``r``, ``q_f dt``, ``q_b dt``."""
    r = np.square(np.asarray(config.noise_std, dtype=np.float64))
    q_f = np.square(np.asarray(config.wrench_walk_std, dtype=np.float64))
    q_b = np.square(np.asarray(config.bias_walk_std, dtype=np.float64))
    return np.concatenate([r, q_f * dt_s, q_b * dt_s])


class WrenchFilter:
    """Kalman filter of the measured wrench with a per-axis bias state, one run.

    The model is separable per axis (``F = I``, ``H = [I I]``, diagonal
    ``Q`` and ``R``, and a tare that leaves ``P`` block-diagonal), so the
    12-state filter is run as six 2-state filters side by side: the same
    equations as a :class:`filterpy.kalman.KalmanFilter` over the 12 states
    (``tests/test_speed_estimation.py`` checks that), at a fraction of its
    per-cycle cost (no 12x12 products or inverse). Its arithmetic is
    :func:`ffexp.estimation.kernels.wrench_update` and ``wrench_tare``, the
    estimator's own for every run of a batch.
    """

    def __init__(self, config: WrenchFilterConfig) -> None:
        from ffexp.estimation import kernels

        self.config = config
        self._k = kernels
        self._dt_s = math.nan
        self._wq = wrench_noise(config, 0.0)
        self._wf = np.zeros(kernels.WF_SIZE)
        self._wf[kernels.WF_P_FF:kernels.WF_P_FF + 6] = 100.0
        self._wf[kernels.WF_P_BB:kernels.WF_P_BB + 6] = 100.0
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
        self._k.wrench_tare(self._wf, self._wq, samples.sum(axis=0), n)
        self.tared = True

    def update(self, samples: F64, dt_s: float) -> None:
        """Predict over ``dt_s`` and update with the mean of this cycle's samples.

        With no samples the filter only predicts (its covariance grows).
        """
        if dt_s != self._dt_s:
            self._dt_s = dt_s
            self._wq = wrench_noise(self.config, dt_s)
        rows = np.ascontiguousarray(samples, dtype=np.float64).reshape(-1, 6)
        self._k.wrench_update(self._wf, self._wq, rows)

    def update_rows(self, rows: list[list[float]], dt_s: float) -> None:
        """:meth:`update` with the samples as rows of six floats."""
        self.update(np.array(rows, dtype=np.float64).reshape(-1, 6), dt_s)

    def _part(self, at: int) -> F64:
        return self._wf[at:at + 6].copy()

    @property
    def wrench(self) -> F64:
        """Filtered wrench (bias removed), TCF."""
        return self._part(self._k.WF_X_F)

    @property
    def bias(self) -> F64:
        """Estimated sensor bias, TCF."""
        return self._part(self._k.WF_X_B)

    @property
    def wrench_std(self) -> F64:
        """1-sigma uncertainty of :attr:`wrench`."""
        return np.sqrt(self._part(self._k.WF_P_FF))

    @property
    def wrench_list(self) -> list[float]:
        """:attr:`wrench` as floats."""
        return self.wrench.tolist()  # type: ignore[no-any-return]

    @property
    def bias_list(self) -> list[float]:
        """:attr:`bias` as floats."""
        return self.bias.tolist()  # type: ignore[no-any-return]
