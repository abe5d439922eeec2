"""State estimation building blocks of :mod:`ffexp.estimator`: wrench and tool-motion Kalman filters
(filterpy), tool-load compensation and a contact detector. No I/O.

Wrench filter
    A Kalman filter over 12 states (six 2-state filters side by side), per TCF axis the
    true wrench ``f`` (random walk, fast) and the sensor bias ``b`` (random
    walk, slow: the Mini45 drifts 0.1-0.4 N over minutes), measured as
    ``z = f + b + noise``. The bias is observable only while the wrench is
    known to be zero, so :meth:`WrenchFilter.tare` feeds N samples taken in
    free space with a pseudo-measurement ``f = 0``; afterwards the bias moves
    only as slowly as its drift allows and the fast state follows the contact.
    All F/T samples that arrive in one controller cycle update the filter once,
    with their mean and the covariance divided by their number.

Motion filter
    Constant-acceleration model per axis (position, velocity, acceleration)
    over the tool's translation and its accumulated rotation vector, both in
    the base frame, measured from the pose once per cycle.

Tool load
    ``w_load = [m R^T g, c x (m R^T g)]`` in the sensor frame for a tool of mass
    ``m`` with centre of mass ``c`` behind the sensor, and its least-squares
    identification (with the bias) from static poses.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Literal

import mujoco
import numpy as np
from filterpy.common import Q_discrete_white_noise
from pydantic import Field, model_validator

from drivers.base.types import F64, Vec3, Vec6
from drivers.config import StrictModel

FloatArray = F64  # the project's alias (drivers.base.types)

GRAVITY_BASE_MPS2: FloatArray = np.array([0.0, 0.0, -9.81])
"""Gravity in the robot base frame (base Z up). In the paper's TCF it is along -X."""


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

    def tare(self, samples: FloatArray) -> None:
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

    def update(self, samples: FloatArray, dt_s: float) -> None:
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
    def wrench(self) -> FloatArray:
        """Filtered wrench (bias removed), TCF."""
        return np.array(self._x_f)

    @property
    def bias(self) -> FloatArray:
        """Estimated sensor bias, TCF."""
        return np.array(self._x_b)

    @property
    def wrench_std(self) -> FloatArray:
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


class MotionFilterConfig(StrictModel):
    """Constant-acceleration model of the tool motion."""

    position_noise_m: float = Field(1e-5, gt=0)
    rotation_noise_rad: float = Field(1e-4, gt=0)
    accel_walk: float = Field(50.0, gt=0, description="Jerk noise spectral density [m/s^3].")


#: Cycles :class:`MotionFilter` looks for its covariance to repeat before it stops looking.
_GAIN_WATCH_CYCLES = 2000


class MotionFilter:
    """Velocity and acceleration of the tool from its pose (base frame).

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
    instead of computed (exact: the same bits as computing them).
    """

    def __init__(self, config: MotionFilterConfig, cycle_s: float) -> None:
        self.config = config
        self.cycle_s = cycle_s
        self._f1 = np.array([[1.0, cycle_s, 0.5 * cycle_s**2], [0.0, 1.0, cycle_s],
                             [0.0, 0.0, 1.0]])
        self._f1_t = self._f1.T.copy()
        self._q1 = Q_discrete_white_noise(dim=3, dt=cycle_s, var=config.accel_walk**2 * cycle_s)
        noise = [config.position_noise_m] * 3 + [config.rotation_noise_rad] * 3
        self._r = np.square(np.asarray(noise, dtype=np.float64))
        self._x = np.zeros((6, 3))  # per axis: value, rate, acceleration
        self._p = np.tile(np.eye(3) * 1e-2, (6, 1, 1))
        self._z = np.zeros(6)
        self._quat = np.zeros(4)
        self._rotvec = np.zeros(3)
        self._rot_prev = np.zeros((3, 3))  # the last cycle's rotation (once _started)
        self._started = False
        self._theta = self._z[3:]  # the accumulated rotation vector: z's own entries
        # the covariance and gain do not depend on the measurements: once the
        # covariance repeats bit for bit, its later values (and the gains) repeat too
        self._watch: dict[bytes, int] | None = {}  # covariance bytes: cycle seen
        self._watch_cycles = _GAIN_WATCH_CYCLES
        self._history: list[tuple[FloatArray, FloatArray]] = []  # (gain, covariance)
        self._cycle: list[tuple[FloatArray, FloatArray]] = []  # once found: its repeats
        self._at = 0  # the next cycle's place in it

    def update(self, pose: FloatArray) -> None:
        """One cycle with the measured 4x4 tool pose (base frame)."""
        r = pose[:3, :3]
        z = self._z
        if not self._started:
            self._started = True
            self._x[:] = 0.0
            self._x[:3, 0] = pose[:3, 3]
            self._x[3:, 0] = self._theta
        else:
            # accumulate the incremental rotation, in the base frame (into z[3:])
            mujoco.mju_mat2Quat(self._quat, (self._rot_prev.T @ r).ravel())
            mujoco.mju_quat2Vel(self._rotvec, self._quat, 1.0)  # its rotation vector
            self._theta += self._rot_prev @ self._rotvec
        self._rot_prev[...] = r
        z[:3] = pose[:3, 3]
        # predict
        x = self._x @ self._f1_t
        cycle = self._cycle
        if cycle:  # the covariance repeats: its gain and covariance as computed before
            k, p = cycle[self._at]
            self._at = (self._at + 1) % len(cycle)
        else:
            k, p = self._gain()
        # update with the value of each axis
        x += k * (z - x[:, 0])[:, None]
        self._x = x
        self._p = p

    def _gain(self) -> tuple[FloatArray, FloatArray]:
        """The gain of this cycle and the covariance after its update, computed; once
        the covariance equals one of an earlier cycle bit for bit, the values from that
        cycle on are kept to be repeated (:attr:`gain_period`)."""
        p = self._f1 @ self._p @ self._f1_t
        p += self._q1
        s = p[:, 0, 0] + self._r
        k = p[:, :, 0] / s[:, None]
        p -= k[:, :, None] * p[:, None, 0, :]
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

    @property
    def twist_base(self) -> FloatArray:
        """[vx, vy, vz, wx, wy, wz] in the base frame."""
        return self._x[:, 1].copy()

    @property
    def accel_base(self) -> FloatArray:
        """Linear and angular acceleration in the base frame."""
        return self._x[:, 2].copy()

    @property
    def accel_linear_view(self) -> FloatArray:
        """The linear part of :attr:`accel_base`, a view of the state (do not modify)."""
        return self._x[:3, 2]

    def twist_tcf(self, pose: FloatArray) -> FloatArray:
        """The twist expressed in the tool frame of ``pose``."""
        r = pose[:3, :3]
        v = self._x[:, 1]
        out = np.empty(6)
        out[:3] = v[:3] @ r
        out[3:] = v[3:] @ r
        return out


class ToolLoad(StrictModel):
    """Mass and centre of mass (sensor frame) of the tool the sensor carries.

    The reading, in our convention, is ``w = w_contact + w_load`` with
    ``w_load = [m R^T (g - a), c x m R^T (g - a)]``: the tool's weight and,
    while it accelerates by ``a`` (base frame), its inertia. Subtracting
    ``w_load`` leaves the contact wrench.
    """

    mass_kg: float = Field(0.0, ge=0)
    com_m: Vec3 = (0.0, 0.0, 0.0)

    def wrench(
        self,
        r_base_sensor: FloatArray,
        accel_base: FloatArray | None = None,
        gravity: FloatArray = GRAVITY_BASE_MPS2,
    ) -> FloatArray:
        """Wrench the tool's weight (and inertia, given ``accel_base``) adds to the reading."""
        g = gravity if accel_base is None else gravity - accel_base
        f = self.mass_kg * (r_base_sensor.T @ g)
        return np.concatenate([f, np.cross(np.asarray(self.com_m), f)])


def skew(v: FloatArray) -> FloatArray:
    """Cross-product matrix: ``skew(a) @ b == a x b``."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


@dataclass(frozen=True)
class ToolLoadFit:
    """Result of :func:`identify_tool_load`."""

    load: ToolLoad
    bias: FloatArray
    residual_rms: FloatArray


def identify_tool_load(
    rotations: FloatArray, wrenches: FloatArray, gravity: FloatArray = GRAVITY_BASE_MPS2
) -> ToolLoadFit:
    """Least-squares tool mass, centre of mass and sensor bias from static poses.

    Args:
        rotations: (K, 3, 3) sensor orientations in the base frame.
        wrenches: (K, 6) static readings (our sign convention).

    The model ``w = [m g_s, (m c) x g_s] + bias`` with ``g_s = R^T g`` is
    linear in ``(m, m c, bias)``; it needs at least three orientations that
    are not all rotations about the gravity axis.
    """
    rotations = np.asarray(rotations, dtype=np.float64)
    wrenches = np.asarray(wrenches, dtype=np.float64)
    k = rotations.shape[0]
    if k < 3 or wrenches.shape != (k, 6):
        raise ValueError("need >= 3 poses with one 6-vector each")
    a = np.zeros((6 * k, 10))
    for i in range(k):
        g_s = rotations[i].T @ gravity
        a[6 * i : 6 * i + 3, 0] = g_s
        a[6 * i : 6 * i + 3, 4:7] = np.eye(3)
        a[6 * i + 3 : 6 * i + 6, 1:4] = -skew(g_s)
        a[6 * i + 3 : 6 * i + 6, 7:10] = np.eye(3)
    sol, _res, rank, _sv = np.linalg.lstsq(a, wrenches.reshape(-1), rcond=None)
    if rank < 10:
        raise ValueError("poses do not excite every parameter: add different orientations")
    mass = float(sol[0])
    com = sol[1:4] / mass if abs(mass) > 1e-9 else np.zeros(3)
    residual = (a @ sol - wrenches.reshape(-1)).reshape(k, 6)
    return ToolLoadFit(
        load=ToolLoad(mass_kg=max(mass, 0.0), com_m=(float(com[0]), float(com[1]), float(com[2]))),
        bias=np.concatenate([sol[4:7], sol[7:10]]),
        residual_rms=np.sqrt(np.mean(residual**2, axis=0)),
    )


class ContactDetectorConfig(StrictModel):
    """Hysteresis and debounce on the filtered contact force.

    ``signal`` picks what is compared: the norm of the force vector, or the
    approach-axis contact force ``f_z = -w[2]``.
    """

    signal: Literal["force_norm", "fz"] = "force_norm"
    on_threshold_n: float = Field(0.3, gt=0)
    off_threshold_n: float = Field(0.1, ge=0)
    debounce_on_s: float = Field(0.01, ge=0)
    debounce_off_s: float = Field(0.05, ge=0)

    @model_validator(mode="after")
    def _hysteresis(self) -> ContactDetectorConfig:
        if self.off_threshold_n >= self.on_threshold_n:
            raise ValueError("off_threshold_n must be below on_threshold_n")
        return self


@dataclass(frozen=True)
class ContactEvent:
    """Contact made or broken at ``time_ns``; ``previous_s`` is how long the
    previous state (free or in contact) lasted."""

    kind: Literal["made", "broken"]
    time_ns: int
    previous_s: float


@dataclass
class ContactDetector:
    """Contact state from the filtered wrench, with hysteresis and debounce.

    Contact is declared once the signal has stayed above ``on_threshold_n``
    for ``debounce_on_s``, and lost once it has stayed below
    ``off_threshold_n`` for ``debounce_off_s``; the event carries the time the
    crossing began, not the time it was confirmed.
    """

    config: ContactDetectorConfig
    in_contact: bool = False
    events: list[ContactEvent] = field(default_factory=list)
    _pending_since_ns: int | None = None
    _state_since_ns: int | None = None

    def signal(self, wrench: FloatArray) -> float:
        """The scalar the thresholds apply to."""
        if self.config.signal == "fz":
            return float(-wrench[2])
        if type(wrench) is np.ndarray and wrench.dtype == np.float64:
            f = wrench[:3]  # np.linalg.norm's own sum of squares and root, without its checks
            return math.sqrt(f.dot(f))
        return float(np.linalg.norm(wrench[:3]))

    def update(self, time_ns: int, wrench: FloatArray) -> ContactEvent | None:
        """Feed one filtered wrench; return the event this sample confirms, if any."""
        if self._state_since_ns is None:
            self._state_since_ns = time_ns
        s = self.signal(wrench)
        crossing = s < self.config.off_threshold_n if self.in_contact else (
            s > self.config.on_threshold_n
        )
        if not crossing:
            self._pending_since_ns = None
            return None
        if self._pending_since_ns is None:
            self._pending_since_ns = time_ns
        hold_s = self.config.debounce_off_s if self.in_contact else self.config.debounce_on_s
        if (time_ns - self._pending_since_ns) * 1e-9 + 1e-12 < hold_s:
            return None
        start = self._pending_since_ns
        event = ContactEvent(
            kind="broken" if self.in_contact else "made",
            time_ns=start,
            previous_s=(start - self._state_since_ns) * 1e-9,
        )
        self.in_contact = not self.in_contact
        self._state_since_ns = start
        self._pending_since_ns = None
        self.events.append(event)
        return event
