"""ATI Mini45 / Net F/T model on top of MuJoCo's force-torque sensor.

Input: the physical wrench the *parent* (sensor body) applies to the tool,
as MuJoCo's ``force``/``torque`` sensors report it in the sensor site frame
(fact sheet sec. 3: a hanging child reads +m g up). The model turns it into
what a Net F/T streams, in our sign convention:

1. sign: wrench the environment exerts on the tool = minus the reading
   (static case). The reading therefore contains the tool load: its weight
   and its inertia (``-m a``), as a real sensor's does;
2. the reading ``delay_s`` old (the sensor's conversion and filter), + bias
   (drawn once per run) + random-walk drift + white noise;
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

:class:`FtSteps` runs a control cycle's physics steps and collects the raw
readings of every step (MuJoCo keeps them: the sensors' ``nsample`` history).
"""

from __future__ import annotations

import mujoco
import numpy as np
from numpy.typing import NDArray

from drivers.base.types import F64, FtSamples, FtStatus
from drivers.description.scene import FtSensorSettings
from drivers.errors import SimulationError
from drivers.world.gate import current_gate

#: Samples' worth of Gaussian draws taken from the generator at once (12 per sample:
#: 6 drift increments, 6 white noise values).
NOISE_BLOCK = 512

#: Samples' worth of timestamps and sequence numbers made at once.
SLAB = 1024

_count_nonzero = np.count_nonzero
_new = object.__new__


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
        from drivers.world import kernels  # numba: imported when a world is built

        # the compiled block's constants (kernels.FT_*: bias, range, tare, 1/res, res, xform)
        self._consts = np.zeros((kernels.FT_XFORM + 6, 6))
        self._consts[kernels.FT_BIAS] = self.bias
        self._consts[kernels.FT_RANGE] = self._range
        self._consts[kernels.FT_INV_RES] = self._inv_res
        self._consts[kernels.FT_RES] = self._res
        self._consts[kernels.FT_XFORM:] = self._xform
        self._consts_bias = self._consts[kernels.FT_BIAS]  # views: rewritten on a change
        self._consts_tare = self._consts[kernels.FT_TARE]
        self._ft_block = kernels.ft_block
        self._row_over = np.zeros(0, dtype=bool)
        self._delay_n = round(settings.delay_s * settings.rate)
        # the last _delay_n readings, not yet sampled, then the newest block: [held; raw]
        self._delay_buf: F64 | None = None
        self.seq = 0
        self._last_block: F64 | None = None  # the last block's wrenches (last_wrench)
        self._gauss = np.zeros((0, 12))  # scaled draws not used yet start at row _used
        self._used = 0
        self._tared = False
        # drift summed ahead (see _drift_rows): for the draws buffer _plan_g, blocks of
        # _plan_n rows from row _plan_base to _plan_end; the next block at _plan_at
        self._plan_g: F64 | None = None
        self._plan_n = self._plan_base = self._plan_end = self._plan_at = 0
        self._plan_rows = np.zeros((0, 6))
        self._plan_prev: F64 | None = None
        self._white = np.zeros((0, 6))  # the white-noise columns of _gauss, contiguous
        # per block size n: bias, 1/resolution and resolution tiled to n rows (a
        # same-shape operation is cheaper than a broadcast one, and gives the same values)
        self._tiled_n = -1
        self._bias_key: F64 | None = None
        self._bias_n = self._inv_res_n = self._res_n = self._range_n = np.zeros((0, 6))
        self._abs_n = np.zeros((0, 6))
        self._over_n = np.zeros((0, 6), dtype=bool)
        self._no_status = np.zeros(0, dtype=np.uint32)
        # sample times and sequence numbers ahead (read-only; blocks take slices):
        # entry j is sample _slab_seq0 + j, taken at _slab_t0 + j * period_ns
        self._slab_seq0 = self._slab_t0 = 0
        self._slab_seq = self._slab_t = np.zeros(0, dtype=np.int64)

    @property
    def last_wrench(self) -> F64 | None:
        """The last sample's wrench (a new array; ``None`` before the first)."""
        block = self._last_block
        return None if block is None else block[-1].copy()

    @property
    def tare_offset(self) -> F64:
        """Software bias subtracted from every sample (Net F/T 0x0042) [N, N m]."""
        return self._tare

    @tare_offset.setter
    def tare_offset(self, value: F64) -> None:
        self._tare = np.asarray(value, dtype=np.float64)
        self._tared = bool(np.any(self._tare != 0.0))
        self._consts_tare[:] = self._tare

    def _draws(self, n: int) -> int:
        """Where the next ``n`` rows of scaled draws (drift increments, white noise)
        start in :attr:`_gauss` (drawn more if needed)."""
        i = self._used
        if self._gauss.shape[0] - i < n:
            left = self._gauss[i:]
            new = self._rng.standard_normal((max(NOISE_BLOCK, n - left.shape[0]), 12))
            new *= self._scale
            self._gauss = np.concatenate((left, new)) if left.shape[0] else new
            self._white = np.ascontiguousarray(self._gauss[:, 6:])
            i = 0
        self._used = i + n
        return i

    def _drift_rows(self, i: int, n: int) -> F64:
        """The drift of rows ``i .. i+n`` of the draws, a block continuing the last.

        Per block the drift is the running sum of the block's increments plus
        the drift before it. When blocks keep their size, the rest of the drawn
        rows are summed ahead the same way in a few array operations (each
        value the same sum in the same order); :meth:`process` takes later
        blocks from that plan without calling this.
        """
        g = self._gauss
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

    def _tile(self, n: int) -> None:
        """The per-row constants for blocks of ``n`` rows."""
        self._tiled_n = n
        self._bias_key = self.bias
        self._bias_n = np.tile(self.bias, (n, 1))
        self._inv_res_n = np.tile(self._inv_res, (n, 1))
        self._res_n = np.tile(self._res, (n, 1))
        self._range_n = np.tile(self._range, (n, 1))
        self._abs_n = np.empty((n, 6))
        self._over_n = np.empty((n, 6), dtype=bool)
        self._no_status = np.zeros(n, dtype=np.uint32)
        self._no_status.flags.writeable = False
        self._row_over = np.zeros(n, dtype=bool)
        self._consts_bias[:] = self.bias

    def _slab(self, seq: int, t0_ns: int, n: int) -> None:
        """Sample times and sequence numbers for the next blocks, from ``seq`` at ``t0_ns``."""
        k = np.arange(max(SLAB, n), dtype=np.int64)
        self._slab_seq0, self._slab_t0 = seq, t0_ns
        self._slab_seq = k + seq
        self._slab_t = k * self.period_ns + t0_ns
        self._slab_seq.flags.writeable = False
        self._slab_t.flags.writeable = False

    def _delayed(self, raw: F64) -> F64:
        """The readings ``delay_s`` older than ``raw``'s (the sensor's path: its
        conversion and filter); before the first, the first reading held. A view of a
        buffer the next call overwrites."""
        n, dn, buf = raw.shape[0], self._delay_n, self._delay_buf
        if buf is not None and buf.shape[0] == dn + n:  # [held; raw] in place
            buf[:dn] = buf[n:]  # the last call's newest dn rows (numpy handles the overlap)
        else:  # the first call, or another block size
            held = np.repeat(raw[:1], dn, axis=0) if buf is None else buf[buf.shape[0] - dn:]
            buf = np.concatenate((held, raw))
            self._delay_buf = buf
            return buf[:n]
        buf[dn:] = raw
        return buf[:n]

    def _block(self, white: F64, raw: F64, drift: F64) -> tuple[F64, NDArray[np.uint32]]:
        """The block's wrenches and status from its white noise, raw readings and drift:
        the numpy form of :func:`drivers.world.kernels.ft_block` (a single row: its
        product goes through ``dgemv``)."""
        # environment (incl. tool load) on the tool, sensor frame: (noise - raw) + drift
        # + bias, in this order
        w = white - raw
        w += drift
        w += self._bias_n
        over = np.greater(np.abs(w, out=self._abs_n), self._range_n, out=self._over_n)
        if _count_nonzero(over):
            row_over = over.any(axis=1)
            np.clip(w, -self._range, self._range, out=w)
            status = np.where(row_over, np.uint32(FtStatus.SATURATION),
                              np.uint32(0)).astype(np.uint32)
        else:
            status = self._no_status
        # tool transform (torque about the TCP = torque about the sensing point + r x f),
        # software bias, then the counts' resolution
        w = w @ self._xform
        if self._tared:  # (x - 0.0 is x: nothing to subtract before a tare)
            w -= self._tare
        w *= self._inv_res_n
        np.rint(w, out=w)
        w *= self._res_n
        return w, status

    def process(self, raw_parent_on_child: F64, t0_ns: int) -> FtSamples:
        """Convert ``(n, 6)`` raw readings (force, torque; sensor frame) sampled from ``t0_ns``.

        The per-block work is a fixed handful of array operations (a block is
        one FRI cycle's samples); the clip runs only when some value exceeds
        its range. The samples' ``time_ns``, ``seq`` and (unsaturated)
        ``status`` are read-only arrays. (:attr:`bias` may be replaced, not
        changed in place: its rows are tiled once per object.)
        """
        raw = raw_parent_on_child
        n = raw.shape[0]
        buf, dn = self._delay_buf, self._delay_n
        if buf is None or buf.shape[0] != dn + n or n < 2:
            if dn:  # the first block, another size, or one row
                raw = self._delayed(raw)
            buf, dn = raw, 0  # (the compiled block's delay: none)
        i = self._used
        if (n == self._plan_n and i == self._plan_at and self._gauss is self._plan_g
                and i + n <= self._plan_end and self.drift is self._plan_prev):
            # the next block of the plan (what _draws and _drift_rows would give)
            self._used = i + n
            rows = self._plan_rows
            at = i - self._plan_base
        else:
            if n == 0:
                return FtSamples()
            i = self._draws(n)
            rows = self._drift_rows(i, n)
            at = 0
        self._plan_at = i + n
        self.drift = self._plan_prev = rows[at + n - 1]
        if n != self._tiled_n or self.bias is not self._bias_key:
            self._tile(n)
        if n >= 2:  # compiled: the same operations (kernels.ft_block)
            w = np.empty((n, 6))
            if self._ft_block(self._white, i, raw, buf, dn, rows, at, self._consts,
                              self._tared, w, self._row_over):
                status = np.where(self._row_over, np.uint32(FtStatus.SATURATION),
                                  np.uint32(0)).astype(np.uint32)
            else:
                status = self._no_status
        else:
            w, status = self._block(self._white[i:i + n], raw, rows[at:at + n])
        self._last_block = w
        seq = self.seq
        self.seq = seq + n
        j = seq - self._slab_seq0
        if not (0 <= j <= self._slab_seq.shape[0] - n
                and t0_ns == self._slab_t0 + j * self.period_ns):
            self._slab(seq, t0_ns, n)
            j = 0
        # FtSamples(time_ns=..., seq=..., wrench=w, status=status) without its __init__
        out: FtSamples = _new(FtSamples)
        out.__dict__ = {"time_ns": self._slab_t[j:j + n], "seq": self._slab_seq[j:j + n],
                        "wrench": w, "status": status}
        return out


class FtSteps:
    """A control cycle's physics steps and the F/T sensor's raw reading after each.

    With the model's force and torque sensors keeping ``substeps`` samples of
    history (MJCF ``nsample``, no delay), one ``mj_step`` call runs the cycle and
    the readings are copied out of MuJoCo's history buffers (the same values as
    ``sensordata`` after each step); otherwise one call per step, ``sensordata``
    copied after each.

    Built while a :class:`~drivers.world.gate.PhysicsGate` is active (a run of a
    batch), the steps go through that gate: the batch's runs are stepped together,
    one dispatch a cycle, each exactly as alone.

    Args:
        model, data: the world's.
        force, torque: the sensor ids (3 values each; torque right after force).
        substeps: physics steps per cycle.
    """

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, force: int, torque: int,
                 substeps: int) -> None:
        self._m, self._d, self._n = model, data, substeps
        self._sensors = (force, torque)
        adr = int(model.sensor_adr[force])
        if int(model.sensor_adr[torque]) != adr + 3:
            raise SimulationError("unexpected sensor layout")
        self.raw = np.zeros((substeps, 6))
        """The last cycle's readings, oldest first (parent on child: force, torque)."""
        self._rows = tuple(self.raw[i] for i in range(substeps))
        self._now = data.sensordata[adr:adr + 6]
        self._history = data.history  # a view of MuJoCo's buffer (fixed for the data's life)
        self._hist = self._history_view()
        # the sensors' history addresses (kernels.history_rows: the view's rows, compiled)
        self._fadr, self._tadr = (int(model.sensor_historyadr[s]) for s in self._sensors)
        from drivers.world import kernels  # numba: imported when a world is built

        self._history_rows = kernels.history_rows
        self._gate = current_gate()
        """The batch's physics gate this world steps through (``None``: alone)."""

    def _history_view(self) -> tuple[F64, int] | None:
        """Both sensors' history buffers as one ``(substeps, 2, 3)`` view (sample,
        force/torque, axis) and the address of the force sensor's cursor; ``None``
        if the model keeps no such history.

        MuJoCo's layout per sensor: ``[user, cursor, times[n], values[n * dim]]``, a
        ring whose newest sample is at the cursor (so the oldest at cursor + 1).
        """
        m, n = self._m, self._n
        force, torque = self._sensors
        hist = self._d.history
        if (m.sensor_history[force, 0] != n or m.sensor_history[torque, 0] != n
                or m.sensor_delay[force] != 0.0 or m.sensor_delay[torque] != 0.0):
            return None
        fadr, tadr = int(m.sensor_historyadr[force]), int(m.sensor_historyadr[torque])
        if tadr <= fadr or hist.shape[0] < tadr + 2 + 4 * n:
            return None
        item = hist.strides[0]
        view = np.lib.stride_tricks.as_strided(
            hist[fadr + 2 + n:], shape=(n, 2, 3), strides=(3 * item, (tadr - fadr) * item, item),
            writeable=False)
        return view, fadr + 1

    @property
    def uses_history(self) -> bool:
        """Whether the readings come from MuJoCo's sensor history (one call per cycle)."""
        return self._hist is not None

    def restart(self) -> None:
        """After the clock was set back: the buffers' times before now (MuJoCo keeps a
        reading only when it is newer than the newest kept)."""
        if self._hist is None:
            return
        m, d, n = self._m, self._d, self._n
        times = d.time - m.opt.timestep * np.arange(n, 0, -1, dtype=np.float64)
        for sid in self._sensors:
            adr = int(m.sensor_adr[sid])
            values = np.tile(d.sensordata[adr:adr + 3], (n, 1))
            mujoco.mj_initSensorHistory(m, d, sid, times, values,
                                        float(d.history[m.sensor_historyadr[sid]]))

    def step(self) -> None:
        """Run the cycle's physics steps; :attr:`raw` then holds their readings.

        Raises:
            SimulationError: the history does not hold this cycle's readings (the
                clock was set back without :meth:`restart`).
        """
        m, d = self._m, self._d
        hist = self._hist
        gate = self._gate
        if hist is None:
            now = self._now
            for row in self._rows:
                if gate is None:
                    mujoco.mj_step(m, d)
                else:
                    gate.step(m, d, 1)
                row[:] = now
            return
        t_start = d.time
        if gate is None:
            mujoco.mj_step(m, d, self._n)
        else:  # stepped with the batch's other runs, in one dispatch
            gate.step(m, d, self._n)
        # the rows of the history view, oldest first (the ring may have started elsewhere:
        # a step outside this class), and the oldest sample's time checked, compiled
        if not self._history_rows(self._history, self._fadr, self._tadr, self._n, t_start,
                                  self.raw):
            raise SimulationError("F/T sensor history: not this cycle's readings")
