"""The step's small geometry and control laws, compiled (numba). Pure: no I/O, no clock.

Imported on first use (numba's import is slow; ``ffexp --help`` never imports it), cached
on disk like :mod:`ffexp.estimation.kernels`, whose rules these follow: no fast-math (no
contraction into fused multiply-adds), and every product that the numpy form made
through BLAS is summed as that BLAS sums it (:func:`~ffexp.estimation.kernels.dot3`
for ``dgemm``, transposed ``dgemv``, ``ddot`` and a vector times a matrix;
:func:`~ffexp.estimation.kernels.dot3_n` for a C-ordered matrix times a vector). What
numpy computes otherwise than libm (``np.arccos`` on this kind of machine) stays
numpy's, between two calls. ``tests/test_step_exact.py`` checks each against the numpy
form it replaces, bit for bit, on random inputs.

* :func:`approach_error`: the approach line's set-point and the pose error's parts
  (:meth:`~ffexp.controllers.laws.ImpedanceController.update`);
* :func:`impedance_out`: ``clip(K e - B twist, -lim, lim)`` per axis, the rotation
  vector scaled from the differences;
* :func:`force_update`: one cycle of eq. (9) with anti-windup
  (:meth:`~ffexp.controllers.laws.ForceController.update`);
* :func:`funnel_geometry`: the tool tip in the funnel's mouth frame and the tool's
  travel along the start TCF's z (:mod:`ffexp.scenarios.funnel`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from drivers.base.blas import dot3, dot3_n
from drivers.base.signatures import F1, F2, I1, b1, f8, i8
from drivers.base.types import F64

#: ``work`` of :func:`approach_error`: the translation error (3), the rotation's cosine
#: (clipped), the rotation vector's unscaled differences (3).
W_TRANS, W_COS, W_DIFF, W_SIZE = 0, 3, 4, 7
#: Rows of :func:`force_update`'s ``gains``: W, F_ref, K_p, K_RI (outside W), the
#: feed-forward's selection, K_i, the integral term's and the output's limits, K_i != 0,
#: the stored integral's bounds.
(G_SEL, G_REF, G_KP, G_KRI, G_FF, G_KI, G_ILO, G_IHI, G_OLO, G_OHI, G_NZ, G_LO,
 G_HI) = range(13)
G_ROWS = 13
#: What a kernel returns when an input holds a NaN: it has computed nothing, the caller
#: takes the float form (which NaN a sum passes on is the order of its operands, which
#: compiled code may swap).
NAN = 2
#: Rows of :func:`force_update`'s ``terms``: p, i, ri, ff, total.
T_P, T_I, T_RI, T_FF, T_TOTAL = range(5)


@njit([(f8, f8, f8)], cache=True)
def clip(x: float, lo: float, hi: float) -> float:
    """``np.clip`` of one float (NaN stays; of two equal values the bound)."""
    x = x if (x > lo or x != x) else lo
    return x if (x < hi or x != x) else hi


@njit([(f8,)], cache=True)
def sign(x: float) -> float:
    """``np.sign`` of one float (NaN stays NaN)."""
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return x if x != x else 0.0


@njit([(F2, F2, F1, f8, F2, F1)], cache=True)
def approach_error(pose: F64, start: F64, direction: F64, travel: float, sp: F64,
                   work: F64) -> bool:
    """The set-point ``travel`` along ``direction`` (start TCF) from ``start`` into ``sp``
    (4x4), and into ``work`` the error's parts: ``R^T (p_sp - p)`` and, of ``R^T R_sp``,
    the clipped cosine of its angle and its antisymmetric differences. False (nothing
    computed) if ``pose`` or ``start`` holds a NaN."""
    for i in range(4):
        for j in range(4):
            if pose[i, j] != pose[i, j] or start[i, j] != start[i, j]:
                return False
    for i in range(4):
        for j in range(4):
            sp[i, j] = start[i, j]
    u0, u1, u2 = direction[0] * travel, direction[1] * travel, direction[2] * travel
    for i in range(3):
        sp[i, 3] = start[i, 3] + dot3_n(start[i, 0], start[i, 1], start[i, 2], u0, u1, u2)
    d0, d1, d2 = sp[0, 3] - pose[0, 3], sp[1, 3] - pose[1, 3], sp[2, 3] - pose[2, 3]
    for i in range(3):
        work[W_TRANS + i] = dot3(pose[0, i], pose[1, i], pose[2, i], d0, d1, d2)
    m = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            m[i, j] = dot3(pose[0, i], pose[1, i], pose[2, i], start[0, j], start[1, j],
                           start[2, j])
    work[W_COS] = clip((m[0, 0] + m[1, 1] + m[2, 2] - 1.0) / 2.0, -1.0, 1.0)
    work[W_DIFF] = m[2, 1] - m[1, 2]
    work[W_DIFF + 1] = m[0, 2] - m[2, 0]
    work[W_DIFF + 2] = m[1, 0] - m[0, 1]
    return True


@njit([(F1, f8, F1, F2, F1)], cache=True)
def impedance_out(work: F64, scale: float, twist: F64, axes: F64, out: F64) -> bool:
    """``out = clip(k e - b twist, lo, hi)`` per axis (``axes`` rows: k, b, lo, hi), the
    error ``e`` from :func:`approach_error`'s ``work``: its translation, and its
    differences times ``scale`` (the rotation vector). False (nothing computed) if
    ``twist``, ``work`` or ``scale`` holds a NaN."""
    if scale != scale:
        return False
    for i in range(6):
        if twist[i] != twist[i]:
            return False
    for i in range(W_SIZE):
        if work[i] != work[i]:
            return False
    for i in range(6):
        e = work[W_TRANS + i] if i < 3 else work[W_DIFF + i - 3] * scale
        out[i] = clip(axes[0, i] * e - axes[1, i] * twist[i], axes[2, i], axes[3, i])
    return True


@njit([(F1, F1, F2, f8, F2)], cache=True)
def force_update(w: F64, integral: F64, gains: F64, dt: float, terms: F64) -> int:
    """One cycle of eq. (9) per axis from the measured wrench ``w``: ``integral``
    stepped in place, the terms into ``terms``' rows; 1 if an output saturated, else 0;
    :data:`NAN` (and nothing changed) if ``w`` or the integral holds a NaN."""
    for k in range(6):
        if w[k] != w[k] or integral[k] != integral[k]:
            return NAN
    saturated = 0
    for k in range(6):
        wk = w[k]
        error = gains[G_SEL, k] * (gains[G_REF, k] + wk)
        pk = gains[G_KP, k] * error
        rik = gains[G_KRI, k] * wk
        ffk = gains[G_FF, k] * -wk
        candidate = integral[k] + error * dt
        ki = gains[G_KI, k]
        raw = pk + clip(ki * candidate, gains[G_ILO, k], gains[G_IHI, k]) + rik + ffk
        o_lo, o_hi = gains[G_OLO, k], gains[G_OHI, k]
        out = clip(raw, o_lo, o_hi)
        if raw != out:
            saturated = 1
            if sign(error) != sign(raw):
                integral[k] = candidate
        else:
            integral[k] = candidate
        if gains[G_NZ, k] != 0.0:
            integral[k] = clip(integral[k], gains[G_LO, k], gains[G_HI, k])
        ik = ki * integral[k]
        terms[T_P, k] = pk
        terms[T_I, k] = ik
        terms[T_RI, k] = rik
        terms[T_FF, k] = ffk
        terms[T_TOTAL, k] = clip(pk + ik + rik + ffk, o_lo, o_hi)
    return saturated


@njit([(F2, F2, F2, F1, F1)], cache=True)
def funnel_geometry(tool: F64, mouth: F64, measured: F64, z_axis: F64, out: F64) -> bool:
    """Into ``out``: the tool tip ``tool`` in the mouth frame (``(p - p_m) R_m``, 3), the
    two headings' difference before wrapping (``atan2`` of the tool's z and the mouth's x
    in the x-y plane), and ``z_axis . p`` of the ``measured`` pose (all 4x4). False
    (nothing computed) if an input holds a NaN."""
    for i in range(4):
        for j in range(4):
            if tool[i, j] != tool[i, j] or mouth[i, j] != mouth[i, j] or \
                    measured[i, j] != measured[i, j]:
                return False
    for i in range(3):
        if z_axis[i] != z_axis[i]:
            return False
    d0, d1, d2 = tool[0, 3] - mouth[0, 3], tool[1, 3] - mouth[1, 3], tool[2, 3] - mouth[2, 3]
    for j in range(3):
        out[j] = dot3(d0, d1, d2, mouth[0, j], mouth[1, j], mouth[2, j])
    out[3] = math.atan2(tool[1, 2], tool[0, 2]) - math.atan2(mouth[1, 0], mouth[0, 0])
    out[4] = dot3(z_axis[0], z_axis[1], z_axis[2], measured[0, 3], measured[1, 3],
                  measured[2, 3])
    return True


#: :func:`safety_motion`'s answers: within the limits, too fast, out of the workspace box.
MOTION_OK, MOTION_SPEED, MOTION_WORKSPACE = 0, 1, 2


@njit([(F1, f8, F2, F2, F1, b1, F1)], cache=True)
def safety_motion(twist: F64, max_speed: float, pose: F64, origin: F64, widths: F64,
                  box: bool, out: F64) -> int:
    """The safety monitor's motion limits: the tool speed ``|twist[:3]|`` (into
    ``out[0]``) against ``max_speed``, then (if ``box``) the offset ``R_o^T (p - p_o)``
    of the tool from ``origin`` (into ``out[1:4]``) against the half-widths; which one
    is crossed first (:data:`MOTION_OK` for none)."""
    speed = math.sqrt(dot3(twist[0], twist[1], twist[2], twist[0], twist[1], twist[2]))
    out[0] = speed
    if speed > max_speed:
        return MOTION_SPEED
    if not box:
        return MOTION_OK
    d0, d1, d2 = pose[0, 3] - origin[0, 3], pose[1, 3] - origin[1, 3], pose[2, 3] - origin[2, 3]
    crossed = False
    for i in range(3):
        v = dot3(origin[0, i], origin[1, i], origin[2, i], d0, d1, d2)
        out[1 + i] = v
        if abs(v) > widths[i]:
            crossed = True
    return MOTION_WORKSPACE if crossed else MOTION_OK


# ---------------------------------------------------------------- the observer

#: "No time" in the observer's int fields.
NONE_NS = np.iinfo(np.int64).min
#: The observer's float state (:class:`ffexp.observer.WrenchObserver`): the position at
#: first contact, the bounds on the target's speed and travel, the impulse, and the last
#: cycle's numbers (:attr:`~ffexp.observer.ObserverState.last`, 8).
OBF_FIRST_Z, OBF_SPEED, OBF_TRAVEL, OBF_IMPULSE, OBF_LAST = 0, 1, 2, 3, 4
OBF_SIZE = 12
#: Its int state: first contact seen, the last cycle's time, since when quiet, since when
#: on a wall or apart (:data:`NONE_NS`: none), ever quiet, the label (:data:`LABELS`),
#: the last cycle's numbers set.
OBI_HAS_FIRST, OBI_LAST_NS, OBI_QUIET, OBI_LOADED, OBI_EVER_QUIET, OBI_LABEL, OBI_HAS_LAST = \
    range(7)
OBI_SIZE = 7
#: Its limits: seated depth, lateral force and torque, wall force ratio, least force,
#: lateral speed, yaw rate, the hold in ns, the target's mass.
(OBL_SEATED, OBL_LAT_F, OBL_LAT_T, OBL_WALL, OBL_MIN_F, OBL_LAT_V, OBL_YAW, OBL_HOLD_NS,
 OBL_MASS) = range(9)
OBL_SIZE = 9
#: The labels by their code in ``OBI_LABEL``.
LABELS = ("unverified", "aligned", "not aligned")


@njit([(F1, I1, F1, i8, f8, b1, f8, f8, f8, f8, f8)], cache=True)
def observer_update(f: F64, i: np.ndarray, lim: F64, t_ns: int, z_m: float, in_contact: bool,
                    f_z: float, f_y: float, t_x: float, v_y: float, w_x: float) -> int:
    """One cycle of the observer (:meth:`ffexp.observer.WrenchObserver.update`, the same
    operations on its state rows ``f``, ``i``); returns the label's code."""
    last_ns = i[OBI_LAST_NS]
    dt = 0.0 if last_ns == NONE_NS else (t_ns - last_ns) / 1_000_000_000
    i[OBI_LAST_NS] = t_ns
    has_first = i[OBI_HAS_FIRST] != 0
    if has_first and dt > 0.0:
        push = 0.0 if 0.0 > f_z else f_z  # Python's max(f_z, 0.0), NaN and -0.0 alike
        f[OBF_SPEED] += push * dt / lim[OBL_MASS]
        f[OBF_TRAVEL] += f[OBF_SPEED] * dt
        f[OBF_IMPULSE] += push * dt
    advance = z_m - f[OBF_FIRST_Z] if has_first else 0.0
    side = in_contact and (abs(f_y) > lim[OBL_LAT_F] or abs(t_x) > lim[OBL_LAT_T])
    quiet = (in_contact and f_z >= lim[OBL_MIN_F] and not side
             and abs(v_y) <= lim[OBL_LAT_V] and abs(w_x) <= lim[OBL_YAW])
    on_wall = (in_contact and abs(f_y) > lim[OBL_LAT_F]
               and abs(f_y) >= lim[OBL_WALL] * (0.0 if 0.0 > f_z else f_z))
    apart = not in_contact and has_first and advance < 0.0
    if not quiet:
        i[OBI_QUIET] = NONE_NS
    elif i[OBI_QUIET] == NONE_NS:
        i[OBI_QUIET] = t_ns
    if not (on_wall or apart):
        i[OBI_LOADED] = NONE_NS
    elif i[OBI_LOADED] == NONE_NS:
        i[OBI_LOADED] = t_ns
    hold_ns = lim[OBL_HOLD_NS]
    inserted = advance - f[OBF_TRAVEL]
    last = f[OBF_LAST:OBF_LAST + 8]
    last[0], last[1], last[2], last[3] = advance, inserted, f_z, f_y
    last[4], last[5], last[6], last[7] = t_x, v_y, w_x, 1.0 if in_contact else 0.0
    i[OBI_HAS_LAST] = 1
    quiet_held = i[OBI_QUIET] != NONE_NS and t_ns - i[OBI_QUIET] >= hold_ns
    if quiet_held and has_first:
        i[OBI_EVER_QUIET] = 1
    label = 0
    if quiet_held and inserted >= lim[OBL_SEATED]:
        label = 1
    elif i[OBI_LOADED] != NONE_NS and t_ns - i[OBI_LOADED] >= hold_ns:
        label = 2
    i[OBI_LABEL] = label
    return label


#: :func:`funnel_observe`'s ``geo``: the tool tip in the mouth frame (3), the heading
#: difference wrapped (:func:`drivers.base.placement.wrap_angle`), the measured pose's
#: travel ``z_axis . p``, whether the placement is within the tolerances.
GEO_YAW, GEO_ALONG, GEO_WITHIN, GEO_SIZE = 3, 4, 5, 6
#: :func:`funnel_observe`'s tolerances: lateral, yaw [deg], least insertion.
TOL_LATERAL, TOL_YAW_DEG, TOL_INSERTION = 0, 1, 2
_DEGREES = 180.0 / math.pi  # math.degrees' factor


@njit([(F2, F2, F2, F1, b1, f8, F1, F1, F1, I1, i8, F1, I1, F1)], cache=True)
def funnel_observe(tool: F64, mouth: F64, measured: F64, z_axis: F64, truth: bool,
                   start_z: float, tol: F64, geo: F64, of: F64, oi: np.ndarray, t_ns: int,
                   f: F64, i: np.ndarray, lim: F64) -> bool:
    """The funnel's watch of one cycle (:meth:`ffexp.scenarios.funnel.FunnelAlignment.
    observe`): :func:`funnel_geometry` into ``geo`` (with ``truth``: the tool in the
    mouth, its heading wrapped and whether it is within ``tol``), then the observer's
    cycle on the estimate's rows ``of``, ``oi`` (:mod:`ffexp.estimation.kernels`' ``OF_*``,
    ``OI_*``) at the travel since the start, ``geo[GEO_ALONG] - start_z`` (first contact
    noted). False (nothing computed) if a pose holds a NaN."""
    if not funnel_geometry(tool, mouth, measured, z_axis, geo):
        return False
    if truth:
        # numba's float % is Python's (fmod, moved to the divisor's sign)
        geo[GEO_YAW] = (geo[GEO_YAW] + math.pi) % (2.0 * math.pi) - math.pi
        within = (abs(geo[1]) <= tol[TOL_LATERAL]
                  and abs(geo[GEO_YAW] * _DEGREES) <= tol[TOL_YAW_DEG]
                  and geo[0] >= tol[TOL_INSERTION])
        geo[GEO_WITHIN] = 1.0 if within else 0.0
    z = geo[GEO_ALONG] - start_z
    in_contact = oi[1] == 1  # OI_IN_CONTACT
    if in_contact and i[OBI_HAS_FIRST] == 0:
        f[OBF_FIRST_Z] = z
        i[OBI_HAS_FIRST] = 1
    # the estimate's f_z (OF_FZ), f_y and t_x (OF_WRENCH), v_y and w_x (OF_TWIST)
    observer_update(f, i, lim, t_ns, z, in_contact, of[24], of[1], of[3], of[19], of[21])
    return True
