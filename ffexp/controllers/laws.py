"""Control laws of the paper, in ffexp's sign conventions. Pure maths: no I/O.

All wrenches are ``[fx, fy, fz, tx, ty, tz]`` in the tool frame (TCF). The
measured wrench ``w`` is what the environment exerts ON the tool
(``docs/conventions.md``), so the contact wrench the tool applies is
``-w``; along the approach axis Z the contact force is ``f_z = -w[2]``.

The paper's eq. (9), written with our signs, over all six axes:

    F* = W (K_p (F_ref - F_c) + K_i ∫ (F_ref - F_c) dt) + (I - W) K_RI w,    F_c = -w

``W`` selects the force-controlled axes (a diagonal 0/1 matrix), ``K_p``,
``K_i`` are the PI gains on them, ``K_RI`` the positive-feedback gains of the
apparent inertia reduction on the others. With W = diag(0,0,1,0,0,0),
K_RI = diag(0, k_yp, 0, k_xp, 0, 0) this is the paper's reduced 3-DOF case:
``F*_z = k_zp (f_ref - f_z) + k_zi ∫ (f_ref - f_z) dt``, ``F*_y = k_yp w[1]``,
``T*_x = k_xp w[3]``. A free tool of mass m pushed by an external force f then
feels ``m a = f + k f``: it accelerates as if its mass were ``m / (1 + k)``.

What is sent as the superposed wrench (FRI addTcpFT) follows the paper's
eq. (2), ``F = M M_d^-1 F* + C + G + F_c`` with ``M_d = M`` and C, G left to
the KRC's own model (f_dyn): on the force-controlled axes the measured contact
force is fed forward, ``F_cmd = F* + F_c`` (``F_c = -w``), so the PI loop
commands the net force on the tool and ``F_cmd = F_ref`` in steady state. On
the inertia-reduction axes ``F_cmd = F*`` alone, as the paper's results
report the applied force there as ``k`` times the contact force
(``contact_feedforward = false`` drops the term everywhere).

The approach phase uses the external impedance law
``F_cmd = K_e (x_sp - x) - B_e x'`` (the paper prints the first term with the
opposite sign), with a set-point moving along a straight line.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import ModuleType
from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from drivers.base.types import F64
from drivers.config import StrictModel, Vec6

AXES = ("x", "y", "z", "rx", "ry", "rz")


def kernels() -> ModuleType:
    """:mod:`ffexp.controllers.kernels`, imported on first use (numba's import is slow)."""
    from ffexp.controllers import kernels as module

    return module


class ForceControlConfig(StrictModel):
    """Gains of eq. (9) over six TCF axes; the defaults are the paper's Method I case I.

    ``force_axes`` is the diagonal of W. Gains on axes where they do not act
    (``kp``/``ki`` outside W, ``k_ri`` inside W) must be zero, so a protocol
    cannot silently carry a gain that does nothing.
    """

    force_axes: tuple[bool, bool, bool, bool, bool, bool] = (
        False, False, True, False, False, False,
    )
    f_ref: Vec6 = Field((0.0, 0.0, 0.8, 0.0, 0.0, 0.0), description="F_ref [N, N m].")
    kp: Vec6 = Field((0.0, 0.0, 1.0, 0.0, 0.0, 0.0), description="K_pFB, dimensionless.")
    ki: Vec6 = Field((0.0, 0.0, 0.07, 0.0, 0.0, 0.0), description="K_iFB, see ki_unit.")
    ki_unit: Literal["per_second", "per_sample"] = Field(
        "per_second",
        description="How ki is read: per second of integrated error (continuous time), "
        "or per controller sample (then ki / cycle_s per second).",
    )
    k_ri: Vec6 = Field(
        (0.0, 0.2, 0.0, 0.5, 0.0, 0.0), description="K_RI positive-feedback gains (k_yp, k_xp)."
    )
    output_limit: Vec6 = Field(
        (20.0, 20.0, 20.0, 2.0, 2.0, 2.0), description="|F*| limit per axis [N, N m]."
    )
    integral_limit: Vec6 = Field(
        (10.0, 10.0, 10.0, 1.0, 1.0, 1.0),
        description="Anti-windup: |K_i * integral| limit per axis [N, N m].",
    )
    contact_feedforward: bool = Field(
        True, description="Eq. (2)'s +F_c on the force-controlled axes (see module doc)."
    )

    @model_validator(mode="after")
    def _gains_where_they_act(self) -> ForceControlConfig:
        for i, axis in enumerate(AXES):
            if self.force_axes[i] and self.k_ri[i] != 0.0:
                raise ValueError(f"k_ri[{i}] ({axis}) must be 0 on a force-controlled axis")
            if not self.force_axes[i] and (self.kp[i] or self.ki[i] or self.f_ref[i]):
                raise ValueError(f"kp/ki/f_ref[{i}] ({axis}) must be 0 outside the force axes")
            if self.output_limit[i] < 0.0 or self.integral_limit[i] < 0.0:
                raise ValueError(f"limits[{i}] ({axis}) must be >= 0")
        return self

    def ki_per_second(self, cycle_s: float) -> F64:
        """K_i in 1/s whatever the file's reading."""
        ki = np.asarray(self.ki, dtype=np.float64)
        return ki / cycle_s if self.ki_unit == "per_sample" else ki


@dataclass
class ForceControlTerms:
    """One cycle of eq. (9), split into its terms (all TCF, [N, N m])."""

    p: F64 = field(default_factory=lambda: np.zeros(6))
    i: F64 = field(default_factory=lambda: np.zeros(6))
    ri: F64 = field(default_factory=lambda: np.zeros(6))
    ff: F64 = field(default_factory=lambda: np.zeros(6))
    total: F64 = field(default_factory=lambda: np.zeros(6))
    saturated: bool = False


class ForceController:
    """Discrete eq. (9) with anti-windup and output limits.

    The integral is a forward-Euler sum at the controller cycle. Anti-windup is
    twofold: the integral term is clamped to ``integral_limit``, and the
    integral does not grow on an axis whose output is saturated in the same
    direction as the error (conditional integration).
    """

    def __init__(self, config: ForceControlConfig, cycle_s: float) -> None:
        if cycle_s <= 0.0:
            raise ValueError("cycle_s must be > 0")
        self.config = config
        self.cycle_s = cycle_s
        self._w_sel = np.asarray(config.force_axes, dtype=np.float64)
        self._kp = np.asarray(config.kp, dtype=np.float64)
        self._ki = config.ki_per_second(cycle_s)
        self._kri = np.asarray(config.k_ri, dtype=np.float64)
        self._f_ref = np.asarray(config.f_ref, dtype=np.float64)
        self._out_lim = np.asarray(config.output_limit, dtype=np.float64)
        self._int_lim = np.asarray(config.integral_limit, dtype=np.float64)
        self._ff_sel = self._w_sel if config.contact_feedforward else np.zeros(6)
        self._integral = np.zeros(6)
        self._out = np.zeros((5, 6))  # the terms' rows (ForceControlTerms' arrays: views)
        o = self._out
        self.terms = ForceControlTerms(p=o[0], i=o[1], ri=o[2], ff=o[3], total=o[4])
        # per axis as floats, computed once as the array form computes them every cycle
        nz = self._ki != 0.0
        int_max = np.full(6, np.inf)
        int_max[nz] = self._int_lim[nz] / np.abs(self._ki[nz])
        int_min = np.full(6, -np.inf)
        int_min[nz] = -self._int_lim[nz] / np.abs(self._ki[nz])
        self._axes: list[tuple[float, ...]] = list(zip(
            self._w_sel.tolist(), self._f_ref.tolist(), self._kp.tolist(),
            (self._kri * (1.0 - self._w_sel)).tolist(), self._ff_sel.tolist(),
            self._ki.tolist(), (-self._int_lim).tolist(), self._int_lim.tolist(),
            (-self._out_lim).tolist(), self._out_lim.tolist(), nz.tolist(),
            int_min.tolist(), int_max.tolist(), strict=True))
        self._kernels = k = kernels()
        self._gains = np.array(self._axes, dtype=np.float64).T.copy()  # k.G_* rows
        assert self._gains.shape == (k.G_ROWS, 6)

    def reset(self) -> None:
        """Forget the integral (on entering the force-controlled phase)."""
        self._integral[:] = 0.0

    @property
    def integral(self) -> F64:
        """∫ (F_ref - F_c) dt per axis [N s, N m s] (a copy)."""
        return self._integral.copy()

    def update(self, w: F64) -> ForceControlTerms:
        """One controller cycle from the measured wrench ``w`` (environment on tool).

        Per axis, compiled (:func:`ffexp.controllers.kernels.force_update`): the six
        axes are independent, and these are the same IEEE operations in the same order
        as the array form (``np.clip`` is :func:`_clip`'s rule; :meth:`update_floats` is
        the same on Python floats), so the terms are bit for bit the same.
        """
        t = self.terms
        saturated = self._kernels.force_update(
            np.asarray(w, dtype=np.float64), self._integral, self._gains, self.cycle_s,
            self._out)
        if saturated == self._kernels.NAN:  # a NaN in: which one comes out is the floats'
            return self.update_floats(w)
        t.saturated = saturated == 1
        return t

    def update_floats(self, w: F64) -> ForceControlTerms:
        """:meth:`update` on Python floats (the reference of the compiled form)."""
        t = self.terms
        dt = self.cycle_s
        p, i, ri, ff, total = [], [], [], [], []
        integral = self._integral.tolist()
        saturated = False
        for k, (wk, axis) in enumerate(zip(np.asarray(w, dtype=np.float64).tolist(),
                                           self._axes, strict=True)):
            sel, f_ref, kp, kri, ff_sel, ki, i_lo, i_hi, o_lo, o_hi, nz, lo, hi = axis
            error = sel * (f_ref + wk)  # F_ref - F_c, with F_c = -w
            pk, rik, ffk = kp * error, kri * wk, ff_sel * -wk
            # tentative integral, then conditional integration where the output saturates
            candidate = integral[k] + error * dt
            raw = pk + _clip(ki * candidate, i_lo, i_hi) + rik + ffk
            out = _clip(raw, o_lo, o_hi)
            if raw != out:
                saturated = True
                if _sign(error) != _sign(raw):
                    integral[k] = candidate
            else:
                integral[k] = candidate
            # the stored integral never exceeds what the clamp lets through
            if nz:
                integral[k] = _clip(integral[k], lo, hi)
            ik = ki * integral[k]
            p.append(pk)
            i.append(ik)
            ri.append(rik)
            ff.append(ffk)
            total.append(_clip(pk + ik + rik + ffk, o_lo, o_hi))
        self._integral[...] = integral
        t.p[...], t.i[...], t.ri[...], t.ff[...], t.total[...] = p, i, ri, ff, total
        t.saturated = saturated
        return t


def _clip(x: float, lo: float, hi: float) -> float:
    """``np.clip`` of one float: ``min(max(x, lo), hi)`` with numpy's rule (NaN stays,
    and of two equal values the bound: ``_NPY_MIN(_NPY_MAX(x, lo), hi)``)."""
    x = x if (x > lo or x != x) else lo
    return x if (x < hi or x != x) else hi


def _sign(x: float) -> float:
    """``np.sign`` of one float (NaN stays NaN, never equal to anything)."""
    return 1.0 if x > 0.0 else -1.0 if x < 0.0 else x if x != x else 0.0


class ImpedanceConfig(StrictModel):
    """External impedance of the approach phase (the paper's Table exp_table).

    ``stiffness`` [N/m, N m/rad] and ``damping`` [N s/m, N m s/rad] are per TCF
    axis. The set-point starts at the pose where the phase starts and moves
    along ``direction`` (TCF, normalised) at ``speed_mps`` for at most
    ``distance_m``.
    """

    stiffness: Vec6 = (0.0, 0.0, 500.0, 0.0, 0.0, 0.0)
    damping: Vec6 = (1.0, 1.0, 1.0, 1.0, 1.0, 1.0)
    direction: tuple[float, float, float] = (0.0, 0.0, 1.0)
    speed_mps: float = Field(0.02, ge=0.0)
    distance_m: float = Field(0.3, ge=0.0)
    output_limit: Vec6 = (20.0, 20.0, 20.0, 2.0, 2.0, 2.0)

    @model_validator(mode="after")
    def _direction_nonzero(self) -> ImpedanceConfig:
        if float(np.linalg.norm(self.direction)) < 1e-9:
            raise ValueError("direction must not be the zero vector")
        if any(k < 0.0 for k in self.stiffness) or any(d < 0.0 for d in self.damping):
            raise ValueError("stiffness and damping must be >= 0")
        return self


def rotation_log(r: F64) -> F64:
    """Rotation vector (axis * angle) of a 3x3 rotation matrix."""
    return np.array(_rotation_log_floats(r))


def _rotation_log_floats(r: F64) -> list[float]:
    """:func:`rotation_log` as three floats: the trace, the differences and the scaling
    on floats (the same IEEE operations as on arrays), the arc cosine and sine numpy's."""
    m = r.tolist()
    cos = _clip((m[0][0] + m[1][1] + m[2][2] - 1.0) / 2.0, -1.0, 1.0)
    angle = float(np.arccos(cos))
    v = [m[2][1] - m[1][2], m[0][2] - m[2][0], m[1][0] - m[0][1]]
    if angle < 1e-9:
        return [0.5 * v[0], 0.5 * v[1], 0.5 * v[2]]
    if np.pi - angle < 1e-6:
        # near pi: axis from the diagonal of (R + I) / 2
        b = (r + np.eye(3)) / 2.0
        k = int(np.argmax(np.diag(b)))
        axis = b[:, k] / np.sqrt(max(b[k, k], 1e-300))
        near_pi: list[float] = (axis * angle).tolist()
        return near_pi
    s = angle / (2.0 * float(np.sin(angle)))
    return [v[0] * s, v[1] * s, v[2] * s]


def pose_error_tcf(pose: F64, setpoint: F64) -> F64:
    """Set-point minus pose as a TCF 6-vector: translation and rotation vector.

    Both are 4x4 base-frame poses of the tool; the error is expressed in the
    current tool frame, where the impedance gains are defined.
    """
    r = pose[:3, :3]
    dp = r.T @ (setpoint[:3, 3] - pose[:3, 3])
    dr = rotation_log(r.T @ setpoint[:3, :3])
    return np.concatenate([dp, dr])


class ImpedanceController:
    """``F_cmd = K_e (x_sp - x) - B_e x'`` with a straight-line moving set-point."""

    def __init__(self, config: ImpedanceConfig) -> None:
        self.config = config
        self._k = np.asarray(config.stiffness, dtype=np.float64)
        self._b = np.asarray(config.damping, dtype=np.float64)
        d = np.asarray(config.direction, dtype=np.float64)
        self._dir = d / np.linalg.norm(d)
        self._lim = np.asarray(config.output_limit, dtype=np.float64)
        # per axis as floats for the output (the array form's elementwise operations)
        self._axes = list(zip(self._k.tolist(), self._b.tolist(), (-self._lim).tolist(),
                              self._lim.tolist(), strict=True))
        self._speed, self._distance = config.speed_mps, config.distance_m
        self._imp_axes = np.array([self._k, self._b, -self._lim, self._lim])
        self._work = np.zeros(7)  # kernels.W_*
        self._kernels = kernels()
        self._start: F64 | None = None
        self._start_r = self._start_p = np.zeros(0)
        self.setpoint = np.eye(4)
        self._sp = np.empty((4, 4))  # the compiled form's set-point (filled each cycle)

    def start(self, pose: F64) -> None:
        """Anchor the line at the current tool pose (4x4, base frame)."""
        self._start = start = pose.copy()
        self._start_r = start[:3, :3]  # views of the anchor (made once a line)
        self._start_p = start[:3, 3]
        self.setpoint = pose.copy()

    def setpoint_at(self, elapsed_s: float) -> F64:
        """The set-point ``elapsed_s`` after :meth:`start` (direction in the start TCF)."""
        if self._start is None:
            raise RuntimeError("ImpedanceController.start() was not called")
        travel = min(self.config.speed_mps * max(elapsed_s, 0.0), self.config.distance_m)
        sp = self._start.copy()
        sp[:3, 3] += self._start[:3, :3] @ (self._dir * travel)
        return sp

    def update(self, pose: F64, twist_tcf: F64, elapsed_s: float,
               out: F64 | None = None) -> F64:
        """Commanded wrench (TCF) for the tool pose and its twist in TCF (into ``out``
        when given, and returned).

        :meth:`setpoint_at`, :func:`pose_error_tcf` and ``np.clip(K e - B twist, -lim,
        lim)`` in one, compiled (:func:`ffexp.controllers.kernels.approach_error` and
        :func:`~ffexp.controllers.kernels.impedance_out`) but for numpy's arc cosine and
        sine between them: the same operations (``tests/test_step_exact.py`` checks it
        against that composition bit for bit). :attr:`setpoint` is then the law's own
        array, filled again next cycle (copy it to keep it).
        """
        start = self._start
        if start is None:
            raise RuntimeError("ImpedanceController.start() was not called")
        k = self._kernels
        # min(speed * max(elapsed_s, 0.0), distance), without the calls
        travel = self._speed * (0.0 if 0.0 > elapsed_s else elapsed_s)
        if self._distance < travel:
            travel = self._distance
        sp = self._sp
        work = self._work
        twist = np.asarray(twist_tcf, dtype=np.float64)
        if k.approach_error(pose, start, self._dir, travel, sp, work):
            angle = float(np.arccos(work[k.W_COS]))
            if angle < 1e-9:
                scale = 0.5
            elif np.pi - angle < 1e-6:  # near pi: rotation_log's own way, on the product
                work[k.W_DIFF:k.W_DIFF + 3] = rotation_log(pose[:3, :3].T @ self._start_r)
                scale = 1.0
            else:
                scale = angle / (2.0 * float(np.sin(angle)))
            if out is None:
                out = np.empty(6)
            if k.impedance_out(work, scale, twist, self._imp_axes, out):
                self.setpoint = sp
                return out
        floats = self.update_floats(pose, twist, elapsed_s)  # a NaN in
        if out is None:
            return floats
        out[...] = floats
        return out

    def update_floats(self, pose: F64, twist_tcf: F64, elapsed_s: float) -> F64:
        """:meth:`update` with numpy's products and the rest on floats (its reference,
        and its form when an input holds a NaN)."""
        self.setpoint = sp = self.setpoint_at(elapsed_s)
        rt = pose[:3, :3].T
        e = (rt @ (sp[:3, 3] - pose[:3, 3])).tolist()
        e += _rotation_log_floats(rt @ self._start_r)
        # np.clip(K e - B twist, -lim, lim), per axis on floats (the same operations)
        return np.array([
            _clip(k * ek - b * vk, lo, hi)
            for (k, b, lo, hi), ek, vk in zip(self._axes, e,
                                              np.asarray(twist_tcf, dtype=np.float64).tolist(),
                                              strict=True)])
