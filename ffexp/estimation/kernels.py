"""The estimator's arithmetic for N runs at once, compiled (numba): one code path for a
batch and for a single run (a batch of one). Pure: no I/O, no clock.

Imported only when an estimator or one of its filters is made (numba's import costs
about 0.4 s; ``ffexp --help`` and completion never import it). Compiled functions are
cached on disk next to this module (``cache=True``): the first run on a fresh checkout
compiles them once (a few seconds), later processes load them.

Bit for bit the numbers of the numpy form they replace: the same IEEE operations in the
same order, no fast-math (so no contraction of ``a * b + c`` into a fused multiply-add),
and where the numpy form went through BLAS (3-vectors times 3x3 matrices, ``dot``) the
sums of three products are made as that BLAS makes them (measured with numpy 2.4's
wheels, OpenBLAS with FMA kernels on x86-64): ``dgemm``, transposed ``dgemv`` and
``ddot`` take ``a0 b0``, then fuse ``a1 b1`` and ``a2 b2`` in turn (:func:`dot3`);
``dgemv`` not transposed fuses ``a0 b0`` into ``a1 b1`` first (:func:`dot3_n`).
``tests/test_estimation_batch.py`` checks both against numpy's own products on random
inputs, so a numpy whose BLAS sums otherwise shows there, not as a changed recording;
the compiled form itself gives the same bits on every machine (``llvm.fma`` rounds
once, in hardware or in software).

Layouts of one run's rows (the estimator's arrays have the run first; a filter used
on its own keeps one run's):

* the wrench filter, ``WF_*``: ``x_f``, ``x_b``, ``p_ff``, ``p_fb``, ``p_bb`` (six each,
  per TCF axis), and its noise, ``WQ_*``: ``r``, ``q_f dt``, ``q_b dt``;
* the contact detector, ``CD_*``: in contact, the pending crossing's start, the state's
  start (``NONE_NS`` for none), and its settings ``CC_*``: thresholds, debounces, the
  signal (0: force norm, 1: ``f_z``);
* the estimator's: the settings ``cfg`` (``CF_*``: the noise, the detector's settings,
  the tool load ``LD_*``), the float state ``fs`` (``FS_*``: the wrench filter, the
  tare's sum), the int state ``ist`` (``IS_*``: the detector, the tare's bookkeeping
  ``ST_*``, the cycle's inputs), the outputs ``of`` (``OF_*``) and ``oi`` (``OI_*``);
* the motion filter: six rows per run of ``x`` (value, rate, acceleration), the run's
  last rotation ``rot[i]`` and its accumulated rotation vector ``theta[i]``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from drivers.base.blas import dot3, dot3_n
from drivers.base.mjlib import c_call, function_addresses
from drivers.base.signatures import F1, F1A, F2, F3, I1, I2, RF1, RF2, RF3, RI1, RU1, b1, f8, i8
from drivers.base.types import F64, FtStatus
from ffexp.controllers.kernels import MOTION_SPEED, MOTION_WORKSPACE, safety_motion

#: The status bit of a saturated F/T sample.
SATURATION = int(FtStatus.SATURATION)
#: "No time" in the int64 time fields.
NONE_NS = np.iinfo(np.int64).min

WF_X_F, WF_X_B, WF_P_FF, WF_P_FB, WF_P_BB = 0, 6, 12, 18, 24
WF_SIZE = 30
WQ_R, WQ_F, WQ_B = 0, 6, 12
WQ_SIZE = 18
CD_IN_CONTACT, CD_PENDING, CD_SINCE = 0, 1, 2
CD_SIZE = 3
CC_ON, CC_OFF, CC_HOLD_ON, CC_HOLD_OFF, CC_FZ = 0, 1, 2, 3, 4
CC_SIZE = 5


def mujoco_functions() -> NDArray[np.int64]:
    """The addresses of MuJoCo's ``mju_mat2Quat`` and ``mju_quat2Vel`` in its shared
    library (the one the ``mujoco`` package loaded): the motion filter calls MuJoCo's
    own rotation functions from compiled code, so its numbers are MuJoCo's bits
    whatever MuJoCo's version (an own copy of them would have to follow MuJoCo's
    arithmetic to the last ulp, near-orthonormal matrices included)."""
    return function_addresses(("mju_mat2Quat", "mju_quat2Vel"))


# ---------------------------------------------------------------- the wrench filter


@njit([(F1, F1, F1, i8)], cache=True)
def wrench_tare(wf: F64, wq: F64, total: F64, n: int) -> None:
    """The tare of one run's filter from the sum of ``n`` free-space samples (the
    bias-only Kalman filter's closed form, ``1/P = 1/100 + n/r``, ``b = P sum / r``)."""
    for k in range(6):
        r = wq[WQ_R + k]
        p_b = 1.0 / (1.0 / 100.0 + n / r)
        wf[WF_X_B + k] = p_b * total[k] / r
        wf[WF_X_F + k] = 0.0
        wf[WF_P_FF + k] = r
        wf[WF_P_FB + k] = 0.0
        wf[WF_P_BB + k] = p_b


@njit([(F1, F1, F2)], cache=True)
def wrench_update(wf: F64, wq: F64, rows: F64) -> None:
    """Predict one run's filter over a cycle and update it with the mean of ``rows``
    ``(n, 6)`` (summed row after row, as numpy's reduce over axis 0); ``n = 0``:
    predict only."""
    for k in range(6):
        wf[WF_P_FF + k] += wq[WQ_F + k]
        wf[WF_P_BB + k] += wq[WQ_B + k]
    n = rows.shape[0]
    if n == 0:
        return
    for k in range(6):
        z = rows[0, k]
        if n > 1:
            for j in range(1, n):
                z += rows[j, k]
            z /= n
        ff, fb, bb = wf[WF_P_FF + k], wf[WF_P_FB + k], wf[WF_P_BB + k]
        s = ff + 2.0 * fb + bb + wq[WQ_R + k] / n
        k_f = (ff + fb) / s
        k_b = (fb + bb) / s
        y = z - wf[WF_X_F + k] - wf[WF_X_B + k]
        wf[WF_X_F + k] += k_f * y
        wf[WF_X_B + k] += k_b * y
        wf[WF_P_FF + k] = ff - k_f * k_f * s
        wf[WF_P_FB + k] = fb - k_f * k_b * s
        wf[WF_P_BB + k] = bb - k_b * k_b * s


@njit([(RF2, RF3, RF2, RF2, RF1, F2, F3)], cache=True)
def motion_gain(f1: F64, p: F64, f1_t: F64, q1: F64, r: F64, k: F64, p_next: F64) -> None:
    """The motion filter's covariance and gain of one cycle, per axis ``a`` of ``p``
    ``(6, 3, 3)``: ``P' = F1 P F1^T + Q1``, ``s = P'[0, 0] + r[a]``, the gain
    ``k[a] = P'[:, 0] / s`` into ``k`` ``(6, 3)`` and ``P' - k P'[0, :]`` into ``p_next``
    (:meth:`MotionFilter._gain <ffexp.estimation.motion_filter.MotionFilter._gain>`'s
    numpy form: its products are ``dgemm``'s, :func:`dot3`)."""
    a = np.empty((3, 3))
    for ax in range(6):
        for i in range(3):
            for j in range(3):
                a[i, j] = dot3(f1[i, 0], f1[i, 1], f1[i, 2], p[ax, 0, j], p[ax, 1, j],
                               p[ax, 2, j])
        for i in range(3):
            for j in range(3):
                p_next[ax, i, j] = dot3(a[i, 0], a[i, 1], a[i, 2], f1_t[0, j], f1_t[1, j],
                                        f1_t[2, j]) + q1[i, j]
        s = p_next[ax, 0, 0] + r[ax]
        for i in range(3):
            k[ax, i] = p_next[ax, i, 0] / s
        r0, r1, r2 = p_next[ax, 0, 0], p_next[ax, 0, 1], p_next[ax, 0, 2]
        for i in range(3):
            ki = k[ax, i]
            p_next[ax, i, 0] -= ki * r0
            p_next[ax, i, 1] -= ki * r1
            p_next[ax, i, 2] -= ki * r2


# ---------------------------------------------------------------- the contact detector


@njit([(F1, f8, f8, f8)], cache=True)
def contact_signal(cc: F64, w0: float, w1: float, w2: float) -> float:
    """The scalar the thresholds apply to: ``-f_z`` or the force's norm (numpy's)."""
    if cc[CC_FZ] != 0.0:
        return -w2
    return math.sqrt(dot3(w0, w1, w2, w0, w1, w2))


@njit([(I1, F1, i8, f8, I1)], cache=True)
def contact_update(cd: np.ndarray, cc: F64, time_ns: int, signal: float,
                   event: np.ndarray) -> bool:
    """One filtered value of one run's detector; an event it confirms goes into
    ``event`` (kind 1 made, 2 broken; the crossing's start; the previous state's start)
    and the result is True."""
    if cd[CD_SINCE] == NONE_NS:
        cd[CD_SINCE] = time_ns
    in_contact = cd[CD_IN_CONTACT] != 0
    crossing = signal < cc[CC_OFF] if in_contact else signal > cc[CC_ON]
    if not crossing:
        cd[CD_PENDING] = NONE_NS
        return False
    if cd[CD_PENDING] == NONE_NS:
        cd[CD_PENDING] = time_ns
    hold_s = cc[CC_HOLD_OFF] if in_contact else cc[CC_HOLD_ON]
    if (time_ns - cd[CD_PENDING]) * 1e-9 + 1e-12 < hold_s:
        return False
    start = cd[CD_PENDING]
    event[0] = 2 if in_contact else 1
    event[1] = start
    event[2] = cd[CD_SINCE]
    cd[CD_IN_CONTACT] = 0 if in_contact else 1
    cd[CD_SINCE] = start
    cd[CD_PENDING] = NONE_NS
    return True


# ---------------------------------------------------------------- the motion filter


@njit([(F2, F2, F1, b1, F2, RF2, F2, I1, F1)], cache=True)
def motion_step(x: F64, rot: F64, theta: F64, started: bool, pose: F64, gain: F64,
                f1_t: F64, mju: NDArray[np.int64], work: F64) -> None:
    """One cycle of one run's motion filter: ``x`` its six rows (value, rate,
    acceleration per axis), ``rot`` its last rotation, ``theta`` its accumulated rotation
    vector (the rotation's measurement), ``pose`` its 4x4 tool pose, ``gain`` (6, 3) the
    cycle's gain (shared by the runs), ``mju`` :func:`mujoco_functions`, ``work`` 16
    floats of scratch. The rotation since the last pose (``rot^T R``, dgemm's sums) as a
    rotation vector (MuJoCo's quaternion and its velocity) is added to ``theta`` in the
    base frame (``rot @ v``, dgemv's sums); then predict (``x @ F1^T``) and update."""
    if not started:
        for a in range(6):
            x[a, 0] = pose[a, 3] if a < 3 else theta[a - 3]
            x[a, 1] = 0.0
            x[a, 2] = 0.0
    else:
        m = work[0:9]
        for i in range(3):
            for j in range(3):
                m[3 * i + j] = dot3(rot[0, i], rot[1, i], rot[2, i],
                                    pose[0, j], pose[1, j], pose[2, j])
        q = work[9:13]
        v = work[13:16]
        c_call(mju[0], (q, m))
        c_call(mju[1], (v, q, 1.0))
        for i in range(3):
            theta[i] += dot3_n(rot[i, 0], rot[i, 1], rot[i, 2], v[0], v[1], v[2])
    for i in range(3):
        for j in range(3):
            rot[i, j] = pose[i, j]
    for a in range(6):
        z = pose[a, 3] if a < 3 else theta[a - 3]
        p0 = dot3(x[a, 0], x[a, 1], x[a, 2], f1_t[0, 0], f1_t[1, 0], f1_t[2, 0])
        p1 = dot3(x[a, 0], x[a, 1], x[a, 2], f1_t[0, 1], f1_t[1, 1], f1_t[2, 1])
        p2 = dot3(x[a, 0], x[a, 1], x[a, 2], f1_t[0, 2], f1_t[1, 2], f1_t[2, 2])
        y = z - p0
        x[a, 0] = p0 + gain[a, 0] * y
        x[a, 1] = p1 + gain[a, 1] * y
        x[a, 2] = p2 + gain[a, 2] * y


@njit([(F2, F2, F1)], cache=True)
def twist_tcf(x: F64, pose: F64, out: F64) -> None:
    """One run's twist in the tool frame of ``pose`` (``v @ R`` per half, dgemv's sums)."""
    for j in range(3):
        out[j] = dot3(x[0, 1], x[1, 1], x[2, 1], pose[0, j], pose[1, j], pose[2, j])
        out[3 + j] = dot3(x[3, 1], x[4, 1], x[5, 1], pose[0, j], pose[1, j], pose[2, j])


@njit([(F2, F3, F2, b1, F3, RF2, F2, I1, F1)], cache=True)
def motion_batch(x: F64, rot: F64, theta: F64, started: bool, poses: F64, gain: F64,
                 f1_t: F64, mju: NDArray[np.int64], work: F64) -> None:
    """:func:`motion_step` for every run: ``x`` (6 N, 3), ``rot`` (N, 3, 3), ``theta``
    (N, 3), ``poses`` (N, 4, 4)."""
    for i in range(poses.shape[0]):
        motion_step(x[6 * i:6 * i + 6], rot[i], theta[i], started, poses[i], gain, f1_t,
                    mju, work)


# ---------------------------------------------------------------- the estimator's cycle

# per run, ``cfg[i]``: the run's settings: the wrench filter's noise (``WQ_*``), the
# contact detector's (``CC_*``) and the tool load's (``LD_*``)
CF_WQ, CF_CC, CF_LD = 0, WQ_SIZE, WQ_SIZE + CC_SIZE
LD_MASS, LD_COMPENSATE, LD_INERTIAL, LD_GRAVITY, LD_SKEW = 0, 1, 2, 3, 6
LD_SIZE = 15
CF_SIZE = CF_LD + LD_SIZE
# per run, ``fs[i]``: the wrench filter (``WF_*``) and the sum of the tare's samples
FS_TARE_SUM = WF_SIZE
FS_SIZE = WF_SIZE + 6
# per run, ``ist[i]`` (int64): the contact detector (``CD_*``), the estimator's own state
# and the cycle's inputs (the link commanding, the cycle's run time, the run's start)
IS_CD = 0
ST_TARED, ST_FIRST, ST_LAST, ST_COUNT, ST_TARE_NS, ST_TARE_SAMPLES = 3, 4, 5, 6, 7, 8
IS_COMMANDING, IS_T_NS, IS_T0_NS = 9, 10, 11
IS_SIZE = 12
# per run, the cycle's outputs: ``of[i]`` (float64) and ``oi[i]`` (int64)
OF_WRENCH, OF_STD, OF_BIAS, OF_TWIST, OF_FZ, OF_PEAK_F, OF_PEAK_T = 0, 6, 12, 18, 24, 25, 26
OF_SIZE = 27
OI_N, OI_IN_CONTACT, OI_EVENT, OI_SATURATED, OI_TARED, OI_TARED_NOW = 0, 1, 2, 5, 6, 7
OI_TARE_SAMPLES, OI_LAST = 8, 9
OI_SIZE = 10


@njit([(F1A, i8)], cache=True)
def _peak(squares: F64, n: int) -> float:
    """``sqrt(max(squares))``, NaN when one is."""
    top = 0.0
    for j in range(n):
        s = squares[j]
        if s != s:
            return math.nan
        if j == 0 or s > top:
            top = s
    return math.sqrt(top)


@njit([(i8, F2, F2, I2, F2, F3, F2, b1, RF2, F2, I1, F2, RI1, RU1, i8, i8, F2, F2, I2,
        F2, F2, I1, F1)], cache=True)
def run_cycle(i: int, cfg: F64, fs: F64, ist: np.ndarray, x: F64, rot: F64, theta: F64,
              started: bool, gain: F64, f1_t: F64, mju: NDArray[np.int64], wrench: F64,
              time_ns: np.ndarray, status: np.ndarray, lo: int, hi: int, pose: F64, of: F64,
              oi: np.ndarray, comp: F64, squares: F64, event: np.ndarray, work: F64) -> None:
    """Run ``i``'s cycle of :func:`estimator_cycle`: its samples ``lo`` to ``hi`` of
    ``wrench``, its pose ``pose``; ``comp``, ``squares``, ``event``, ``work``: scratch
    (``comp`` and ``squares`` as long as ``wrench``)."""
    n = hi - lo
    w, ofi, oii, sti = wrench[lo:hi], of[i], oi[i], ist[i]
    wfi, tare_sum = fs[i, :WF_SIZE], fs[i, FS_TARE_SUM:FS_SIZE]
    wq, cc, ldi = cfg[i, CF_WQ:CF_CC], cfg[i, CF_CC:CF_LD], cfg[i, CF_LD:CF_SIZE]
    cd, t0_ns = sti[IS_CD:IS_CD + CD_SIZE], sti[IS_T0_NS]
    xi = x[6 * i:6 * i + 6]
    rows = comp[lo:hi]
    # tool-load compensation (the acceleration the motion filter had last cycle)
    if ldi[LD_COMPENSATE] != 0.0 and n:
        g0, g1, g2 = ldi[LD_GRAVITY], ldi[LD_GRAVITY + 1], ldi[LD_GRAVITY + 2]
        if ldi[LD_INERTIAL] != 0.0:
            g0, g1, g2 = g0 - xi[0, 2], g1 - xi[1, 2], g2 - xi[2, 2]
        m = ldi[LD_MASS]
        f0 = m * dot3(g0, g1, g2, pose[0, 0], pose[1, 0], pose[2, 0])
        f1 = m * dot3(g0, g1, g2, pose[0, 1], pose[1, 1], pose[2, 1])
        f2 = m * dot3(g0, g1, g2, pose[0, 2], pose[1, 2], pose[2, 2])
        sk = ldi[LD_SKEW:LD_SKEW + 9]
        t0 = dot3_n(sk[0], sk[1], sk[2], f0, f1, f2)
        t1 = dot3_n(sk[3], sk[4], sk[5], f0, f1, f2)
        t2 = dot3_n(sk[6], sk[7], sk[8], f0, f1, f2)
        for j in range(n):
            rows[j, 0] = w[j, 0] - f0
            rows[j, 1] = w[j, 1] - f1
            rows[j, 2] = w[j, 2] - f2
            rows[j, 3] = w[j, 3] - t0
            rows[j, 4] = w[j, 4] - t1
            rows[j, 5] = w[j, 5] - t2
    else:
        rows[:] = w
    tared = sti[ST_TARED] != 0
    oii[OI_N] = n
    oii[OI_EVENT] = 0
    oii[OI_TARED_NOW] = 0
    # the peaks (bias removed once tared) and the saturation bit
    if n:
        sti[ST_LAST] = time_ns[hi - 1] - t0_ns
        sat = 0
        for j in range(lo, hi):
            if status[j] & SATURATION:
                sat = 1
        oii[OI_SATURATED] = sat
        sq = squares[:, lo:hi]
        for j in range(n):
            if tared:
                s0 = rows[j, 0] - wfi[WF_X_B]
                s1 = rows[j, 1] - wfi[WF_X_B + 1]
                s2 = rows[j, 2] - wfi[WF_X_B + 2]
                s3 = rows[j, 3] - wfi[WF_X_B + 3]
                s4 = rows[j, 4] - wfi[WF_X_B + 4]
                s5 = rows[j, 5] - wfi[WF_X_B + 5]
            else:
                s0, s1, s2, s3, s4, s5 = w[j, 0], w[j, 1], w[j, 2], w[j, 3], w[j, 4], w[j, 5]
            sq[0, j] = s0 * s0 + s1 * s1 + s2 * s2
            sq[1, j] = s3 * s3 + s4 * s4 + s5 * s5
        ofi[OF_PEAK_F] = _peak(sq[0], n)
        ofi[OF_PEAK_T] = _peak(sq[1], n)
    else:
        oii[OI_SATURATED] = 0
        ofi[OF_PEAK_F] = 0.0
        ofi[OF_PEAK_T] = 0.0
    # the tool's motion and twist
    motion_step(xi, rot[i], theta[i], started, pose, gain, f1_t, mju, work)
    twist_tcf(xi, pose, ofi[OF_TWIST:OF_TWIST + 6])
    # the tare, then the wrench filter and the contact detector
    if not tared:
        if n:
            for j in range(n):
                for k in range(6):
                    if sti[ST_COUNT] == 0 and j == 0:
                        tare_sum[k] = rows[j, k]
                    else:
                        tare_sum[k] += rows[j, k]
            sti[ST_COUNT] += n
            if sti[ST_FIRST] == NONE_NS:
                sti[ST_FIRST] = time_ns[lo] - t0_ns
        first, last, count = sti[ST_FIRST], sti[ST_LAST], sti[ST_COUNT]
        if first != NONE_NS and last != NONE_NS and sti[IS_COMMANDING] != 0:
            # the samples cover [first, last] plus one sample period
            period_ns = (last - first) / max(count - 1, 1)
            if not last - first + period_ns < sti[ST_TARE_NS]:
                wrench_tare(wfi, wq, tare_sum, count)
                sti[ST_TARED] = 1
                sti[ST_TARE_SAMPLES] = count
                oii[OI_TARED_NOW] = 1
    else:
        wrench_update(wfi, wq, rows)
    if sti[ST_TARED] != 0 and oii[OI_TARED_NOW] == 0:
        sig = contact_signal(cc, wfi[WF_X_F], wfi[WF_X_F + 1], wfi[WF_X_F + 2])
        if contact_update(cd, cc, sti[IS_T_NS], sig, event):
            oii[OI_EVENT] = event[0]
            oii[OI_EVENT + 1] = event[1]
            oii[OI_EVENT + 2] = event[2]
    oii[OI_IN_CONTACT] = cd[CD_IN_CONTACT]
    oii[OI_TARED] = sti[ST_TARED]
    oii[OI_TARE_SAMPLES] = sti[ST_TARE_SAMPLES]
    oii[OI_LAST] = sti[ST_LAST]
    for k in range(6):
        ofi[OF_WRENCH + k] = wfi[WF_X_F + k]
        ofi[OF_STD + k] = math.sqrt(wfi[WF_P_FF + k])
        ofi[OF_BIAS + k] = wfi[WF_X_B + k]
    ofi[OF_FZ] = -wfi[WF_X_F + 2]


@njit([(F2, F2, I2, F2, F3, F2, b1, RF2, F2, I1, F2, RI1, RU1, I1, F3, F2, I2)], cache=True)
def estimator_cycle(cfg: F64, fs: F64, ist: np.ndarray, x: F64, rot: F64, theta: F64,
                    started: bool, gain: F64, f1_t: F64, mju: NDArray[np.int64], wrench: F64,
                    time_ns: np.ndarray, status: np.ndarray, offsets: np.ndarray, poses: F64,
                    of: F64, oi: np.ndarray) -> None:
    """One cycle of every run's estimator (see :mod:`ffexp.estimation`): run ``i``'s
    settings ``cfg[i]``, its state ``fs[i]`` and ``ist[i]`` (with this cycle's link state
    and times), its motion filter's rows of ``x``, ``rot[i]`` and ``theta[i]``; its
    samples are ``wrench[offsets[i]:offsets[i + 1]]`` (with their times and status
    words), its pose ``poses[i]``. Outputs into ``of[i]``, ``oi[i]``."""
    comp = np.empty((wrench.shape[0], 6))
    squares = np.empty((2, wrench.shape[0]))
    event = np.zeros(3, dtype=np.int64)
    work = np.empty(16)
    for i in range(poses.shape[0]):
        run_cycle(i, cfg, fs, ist, x, rot, theta, started, gain, f1_t, mju, wrench, time_ns,
                  status, offsets[i], offsets[i + 1], poses[i], of, oi, comp, squares, event,
                  work)


@njit([(F2, F2, I2, F2, F3, F2, b1, RF2, F2, I1, F2, RI1, RU1, F2, b1, i8, i8, F2,
        I2)], cache=True)
def single_cycle(cfg: F64, fs: F64, ist: np.ndarray, x: F64, rot: F64, theta: F64,
                 started: bool, gain: F64, f1_t: F64, mju: NDArray[np.int64], wrench: F64,
                 time_ns: np.ndarray, status: np.ndarray, pose: F64, commanding: bool,
                 t_ns: int, t0_ns: int, of: F64, oi: np.ndarray) -> None:
    """:func:`estimator_cycle` of a single run (a batch of one), its cycle's inputs as
    arguments: every sample of ``wrench`` is the run's, ``pose`` its 4x4 tool pose."""
    n = wrench.shape[0]
    sti = ist[0]
    sti[IS_COMMANDING] = commanding
    sti[IS_T_NS] = t_ns
    sti[IS_T0_NS] = t0_ns
    run_cycle(0, cfg, fs, ist, x, rot, theta, started, gain, f1_t, mju, wrench, time_ns,
              status, 0, n, pose, of, oi, np.empty((n, 6)), np.empty((2, n)),
              np.zeros(3, dtype=np.int64), np.empty(16))


# ---------------------------------------------------------------- with the safety checks

#: :func:`checked_cycle`'s answers: none holds, or the first of the safety monitor's
#: conditions that does (:mod:`ffexp.safety`, in its order).
(SAFE, STOP_SATURATED, STOP_FORCE, STOP_TORQUE, STOP_STALE, STOP_LINK, STOP_SPEED,
 STOP_WORKSPACE) = range(8)
#: The safety monitor's float row ``sf``: its limits (force, torque, speed, staleness in
#: ns, the workspace's half-widths), the workspace box's origin (4x4, row by row) and
#: the motion check's outputs (the speed, the offset).
SF_FORCE, SF_TORQUE, SF_SPEED, SF_STALE_NS, SF_WIDTHS, SF_ORIGIN, SF_MOTION = 0, 1, 2, 3, 4, 7, 23
SF_SIZE = 27
#: Its int row ``si``: consecutive bad link cycles, the cycles that end the run, whether
#: the box has its origin.
SI_BAD_LINK, SI_LINK_LOST, SI_HAS_ORIGIN = 0, 1, 2
SI_SIZE = 3


@njit([(F1, I1, i8, b1, b1, b1, b1, F2, F1, I1)], cache=True)
def safety_check(ofi: F64, oii: np.ndarray, t_ns: int, connect: bool, moving: bool,
                 healthy: bool, commanding: bool, pose: F64, sf: F64, si: np.ndarray) -> int:
    """:meth:`ffexp.safety.SafetyMonitor.check` on one run's estimate (``of``/``oi``
    rows): which condition holds first (:data:`SAFE` for none). ``connect``: the phase
    is CONNECT; ``moving``: APPROACH or ALIGN."""
    if oii[OI_N]:
        if oii[OI_SATURATED] == 1:
            return STOP_SATURATED
        if ofi[OF_PEAK_F] > sf[SF_FORCE]:
            return STOP_FORCE
        if ofi[OF_PEAK_T] > sf[SF_TORQUE]:
            return STOP_TORQUE
    last = oii[OI_LAST]
    since_ns = t_ns - (0 if last == NONE_NS else last)
    if since_ns > sf[SF_STALE_NS]:
        return STOP_STALE
    bad = not healthy or (not connect and not commanding)
    si[SI_BAD_LINK] = si[SI_BAD_LINK] + 1 if bad else 0
    if si[SI_BAD_LINK] >= si[SI_LINK_LOST]:
        return STOP_LINK
    if moving:
        origin = sf[SF_ORIGIN:SF_ORIGIN + 16].reshape((4, 4))
        crossed = safety_motion(ofi[OF_TWIST:OF_TWIST + 6], sf[SF_SPEED], pose, origin,
                                sf[SF_WIDTHS:SF_WIDTHS + 3], si[SI_HAS_ORIGIN] != 0,
                                sf[SF_MOTION:SF_MOTION + 4])
        if crossed == MOTION_SPEED:
            return STOP_SPEED
        if crossed == MOTION_WORKSPACE:
            return STOP_WORKSPACE
    return SAFE


#: A single run's state packed in two rows, so its cycle is one call of few arguments
#: (each array argument costs a compiled call's dispatch about 0.2 us, more with cold
#: caches): the floats ``P_*`` (the settings ``cfg``, the state ``fs``, the outputs
#: ``of``, the motion filter's ``x``, ``rot``, ``theta`` and ``F1^T``, the safety
#: monitor's ``SF_*``) and the ints ``Q_*`` (``ist``, ``oi``, the MuJoCo functions, the
#: safety monitor's ``SI_*``, the motion filter's place in its table of gains ``Q_GAIN``).
P_CFG = 0
P_FS = P_CFG + CF_SIZE
P_OF = P_FS + FS_SIZE
P_MOTION = P_OF + OF_SIZE  # x (6, 3), rot (3, 3), theta (3), F1^T (3, 3)
MOTION_SIZE = 18 + 9 + 3 + 9
P_SF = P_MOTION + MOTION_SIZE
P_SIZE = P_SF + SF_SIZE
Q_IST = 0
Q_OI = Q_IST + IS_SIZE
Q_MJU = Q_OI + OI_SIZE
Q_SI = Q_MJU + 2
Q_GAIN = Q_SI + SI_SIZE
Q_SIZE = Q_GAIN + 1


#: :func:`checked_cycle`'s flags beside the check's answer (``& R_CHECK``).
R_CHECK, R_IN_CONTACT, R_EVENT = 15, 16, 32


@njit([(F1, I1, RF2, F2, RI1, RU1, F2, b1, b1, i8, i8, b1, b1, b1, b1)], cache=True)
def checked_cycle(fb: F64, ib: np.ndarray, gain: F64, wrench: F64, time_ns: np.ndarray,
                  status: np.ndarray, pose: F64, started: bool, commanding: bool, t_ns: int,
                  t0_ns: int, healthy: bool, connect: bool, moving: bool, check: bool) -> int:
    """:func:`single_cycle` on a single run's packed rows ``fb``, ``ib`` (``P_*``,
    ``Q_*``) and then, with ``check``, :func:`safety_check` on its estimate, in one call:
    the check's answer (:data:`SAFE` without) with the flags :data:`R_IN_CONTACT` and
    :data:`R_EVENT` (the estimate's contact, a contact event this cycle) set.

    ``gain``: the motion filter's gains one after the other, six rows each (``(6 n,
    3)``); this cycle's is the one at ``ib[Q_GAIN]``, which moves on to the next (after
    the last, the first): a table of one gain is that gain every cycle, a filter's
    repeating cycle of gains (:attr:`MotionFilter.gain_period
    <ffexp.estimation.motion_filter.MotionFilter.gain_period>`) is stepped through here."""
    at = ib[Q_GAIN]
    g = gain[6 * at:6 * at + 6]
    ib[Q_GAIN] = 0 if 6 * (at + 1) >= gain.shape[0] else at + 1
    m = P_MOTION
    x = fb[m:m + 18].reshape((6, 3))
    rot = fb[m + 18:m + 27].reshape((1, 3, 3))
    theta = fb[m + 27:m + 30].reshape((1, 3))
    f1_t = fb[m + 30:m + 39].reshape((3, 3))
    cfg = fb[P_CFG:P_FS].reshape((1, CF_SIZE))
    fs = fb[P_FS:P_OF].reshape((1, FS_SIZE))
    of = fb[P_OF:P_MOTION].reshape((1, OF_SIZE))
    ist = ib[Q_IST:Q_OI].reshape((1, IS_SIZE))
    oi = ib[Q_OI:Q_MJU].reshape((1, OI_SIZE))
    single_cycle(cfg, fs, ist, x, rot, theta, started, g, f1_t, ib[Q_MJU:Q_SI], wrench,
                 time_ns, status, pose, commanding, t_ns, t0_ns, of, oi)
    code = SAFE
    if check:
        code = safety_check(of[0], oi[0], t_ns, connect, moving, healthy, commanding, pose,
                            fb[P_SF:P_SIZE], ib[Q_SI:Q_GAIN])
    if oi[0, OI_IN_CONTACT] != 0:
        code |= R_IN_CONTACT
    if oi[0, OI_EVENT] != 0:
        code |= R_EVENT
    return code
