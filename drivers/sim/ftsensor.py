"""ATI Mini45 / Net F/T model on top of MuJoCo's force-torque sensor.

Input: the physical wrench the *parent* (sensor body) applies to the tool,
as MuJoCo's ``force``/``torque`` sensors report it in the sensor site frame
(fact sheet sec. 3: a hanging child reads +m g up). The model turns it into
what a Net F/T streams, in our sign convention:

1. sign: wrench the environment exerts on the tool = minus the reading
   (static case). The reading therefore contains the tool load: its weight
   and its inertia (``-m a``), as a real sensor's does;
2. + bias (drawn once per run) + random-walk drift + white noise;
3. saturation: any gauge axis beyond the calibration range is clipped and
   sets status bit 0x00020000 (in the sensor frame, before the tool transform);
4. tool transform to the TCP (torque shifted by ``r x f``), then
   quantisation to the counts' resolution (1/16 N, 1/752 N m for SI-145-5).

All randomness comes from one seeded :class:`numpy.random.Generator`; samples
are processed in blocks (one block per FRI cycle) without Python loops. The
Gaussian draws are taken from the generator :data:`NOISE_BLOCK` samples at a
time and used in order, which is the very stream per-block draws give (the
generator fills arrays element by element), so a seed's samples do not depend
on how they are blocked.
"""

from __future__ import annotations

import numpy as np

from drivers.base.types import F64, FtSamples, FtStatus
from drivers.sim.scene import FtSensorSettings

#: Samples' worth of Gaussian draws taken from the generator at once (12 per sample:
#: 6 drift increments, 6 white noise values).
NOISE_BLOCK = 512


class FtSensorModel:
    """Turns blocks of raw MuJoCo sensor readings into Net F/T-like samples.

    Args:
        settings: the scene's sensor settings.
        rng: the generator all noise is drawn from.
        r_site_in_tcf: position of the sensing point in the TCF [m] (TCF axes
            equal the sensor axes in our model).
    """

    def __init__(self, settings: FtSensorSettings, rng: np.random.Generator,
                 r_site_in_tcf: F64) -> None:
        self.settings = settings
        self._rng = rng
        self.period_ns = round(1e9 / settings.rate)
        dt = 1.0 / settings.rate
        f_res, t_res = settings.resolution
        self._res = np.array([f_res] * 3 + [t_res] * 3)
        self._range = np.asarray(settings.range, dtype=np.float64)
        n_f, n_t = settings.noise_std
        self._noise = np.array([n_f] * 3 + [n_t] * 3)
        d_f, d_t = settings.drift_density
        self._drift_step = np.array([d_f] * 3 + [d_t] * 3) * np.sqrt(dt)
        b_f, b_t = settings.bias_std
        self.bias = rng.normal(0.0, 1.0, 6) * np.array([b_f] * 3 + [b_t] * 3)
        self.drift = np.zeros(6)
        self._tare = np.zeros(6)
        self._r = np.asarray(r_site_in_tcf, dtype=np.float64)
        rx, ry, rz = self._r
        # Row-vector tool transform: [f, t_tcp] = [f, t_site] @ xform, t_tcp = t_site + r x f.
        self._xform = np.eye(6)
        self._xform[:3, 3:] = np.array([[0.0, -rz, ry], [rz, 0.0, -rx], [-ry, rx, 0.0]]).T
        self._scale = np.concatenate([self._drift_step, self._noise])
        self._inv_res = 1.0 / self._res
        self._min_range = float(self._range.min())
        self._offsets_ns = np.zeros(0, dtype=np.int64)
        self._counts = np.zeros(0, dtype=np.int64)
        self.seq = 0
        self.last_wrench: F64 | None = None
        self._gauss = np.zeros((0, 12))  # scaled draws not used yet start at row _used
        self._used = 0
        self._tared = False
        # drift summed ahead (see _drift_rows): for the draws buffer _plan_g, blocks of
        # _plan_n rows from row _plan_base to _plan_end; the next block at _plan_at
        self._plan_g: F64 | None = None
        self._plan_n = self._plan_base = self._plan_end = self._plan_at = 0
        self._plan_rows = np.zeros((0, 6))
        self._plan_prev: F64 | None = None

    @property
    def tare_offset(self) -> F64:
        """Software bias subtracted from every sample (Net F/T 0x0042) [N, N m]."""
        return self._tare

    @tare_offset.setter
    def tare_offset(self, value: F64) -> None:
        self._tare = np.asarray(value, dtype=np.float64)
        self._tared = bool(np.any(self._tare != 0.0))

    def _draws(self, n: int) -> int:
        """Where the next ``n`` rows of scaled draws (drift increments, white noise)
        start in :attr:`_gauss` (drawn more if needed)."""
        i = self._used
        if self._gauss.shape[0] - i < n:
            left = self._gauss[i:]
            new = self._rng.standard_normal((max(NOISE_BLOCK, n - left.shape[0]), 12))
            new *= self._scale
            self._gauss = np.concatenate((left, new)) if left.shape[0] else new
            i = 0
        self._used = i + n
        return i

    def _drift_rows(self, i: int, n: int) -> F64:
        """The drift of rows ``i .. i+n`` of the draws, a block continuing the last.

        Per block the drift is the running sum of the block's increments plus
        the drift before it. When blocks keep their size, the rest of the drawn
        rows are summed ahead the same way in a few array operations (each
        value the same sum in the same order) and later blocks take their rows.
        """
        g = self._gauss
        if (g is self._plan_g and i == self._plan_at and n == self._plan_n
                and i + n <= self._plan_end and self.drift is self._plan_prev):
            base = i - self._plan_base
            return self._plan_rows[base:base + n]
        k = (g.shape[0] - i) // n
        if k < 2:
            self._plan_g = None
            drift = np.add.accumulate(g[i:i + n, :6], axis=0)  # cumsum
            drift += self.drift
            return drift
        c = np.add.accumulate(g[i:i + k * n, :6].reshape(k, n, 6), axis=1)
        start = np.empty((k, 6))  # the drift before each block: a running sum of block ends
        start[0] = self.drift
        start[1:] = c[:-1, -1]
        start = np.add.accumulate(start, axis=0)
        c += start[:, None, :]
        self._plan_g, self._plan_n, self._plan_base = g, n, i
        self._plan_end = i + k * n
        self._plan_rows = c.reshape(k * n, 6)
        return self._plan_rows[:n]

    def process(self, raw_parent_on_child: F64, t0_ns: int) -> FtSamples:
        """Convert ``(n, 6)`` raw readings (force, torque; sensor frame) sampled from ``t0_ns``.

        The per-block work is a fixed handful of array operations (a block is
        one FRI cycle's samples); the saturation test and clip run only when
        some value exceeds the smallest range.
        """
        n = raw_parent_on_child.shape[0]
        if n == 0:
            return FtSamples()
        i = self._draws(n)
        drift = self._drift_rows(i, n)
        self._plan_at = i + n
        self.drift = self._plan_prev = drift[-1]
        # environment (incl. tool load) on the tool, sensor frame
        w = self._gauss[i:i + n, 6:] - raw_parent_on_child
        w += drift
        w += self.bias
        if np.abs(w).max() > self._min_range:
            over = (np.abs(w) > self._range).any(axis=1)
            np.clip(w, -self._range, self._range, out=w)
            status = np.where(over, np.uint32(FtStatus.SATURATION), np.uint32(0)).astype(np.uint32)
        else:
            status = np.zeros(n, dtype=np.uint32)
        # tool transform (torque about the TCP = torque about the sensing point + r x f),
        # software bias, then the counts' resolution
        w = w @ self._xform
        if self._tared:  # (x - 0.0 is x: nothing to subtract before a tare)
            w -= self._tare
        w *= self._inv_res
        np.rint(w, out=w)
        w *= self._res
        self.last_wrench = w[-1].copy()
        if n != self._offsets_ns.shape[0]:
            self._counts = np.arange(n, dtype=np.int64)
            self._offsets_ns = self.period_ns * self._counts
        seq = self.seq
        self.seq = seq + n
        return FtSamples(time_ns=self._offsets_ns + t0_ns, seq=self._counts + seq, wrench=w,
                         status=status)
