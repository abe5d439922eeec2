"""The world's per-cycle arithmetic, compiled (numba). Pure: no I/O, no clock.

Imported only when a world is built (numba's import costs about 0.4 s; ``ffexp --help``
never imports it). Compiled functions are cached on disk next to this module
(``cache=True``): a fresh checkout compiles them once (a few seconds), later processes
load them.

Bit for bit the numbers of the numpy form they replace: the same IEEE operations in the
same order, no fast-math (no contraction of ``a * b + c`` into a fused multiply-add
unless written as ``fma``). Where the numpy form went through BLAS, the products are
summed as OpenBLAS makes them (:mod:`drivers.base.blas`; ``dgemm`` of ``k = 6``: each
product fused in turn into a zeroed accumulator, see :func:`ft_block`).
``tests/test_world_kernels.py`` checks every kernel against its numpy form (or the
MuJoCo bindings' calls) on random inputs.
"""

from __future__ import annotations

import math
from typing import Any

import mujoco
import numpy as np
from numba import njit, types
from numba.extending import intrinsic
from numba.np.numpy_support import carray
from numpy.typing import NDArray

from drivers.base.blas import dot3, fma
from drivers.base.mjlib import c_call, function_addresses
from drivers.base.signatures import (
    B1,
    F1,
    F2,
    F2A,
    F3,
    I1,
    I32_1A,
    I32_2,
    I32_2A,
    RF1,
    RF2,
    RF2A,
    b1,
    f8,
    i8,
)
from drivers.base.types import F64

__all__ = [
    "FILL_ARRAYS",
    "FILL_DIMS",
    "FT_BIAS",
    "FT_INV_RES",
    "FT_RANGE",
    "FT_RES",
    "FT_TARE",
    "FT_XFORM",
    "MUJOCO",
    "POSE_BODIES",
    "POSE_CMD",
    "POSE_TCP",
    "POST_DIVERGED",
    "POST_INERTIA",
    "POST_TOUCHING",
    "arm_warnings",
    "end_state",
    "fill_state",
    "ft_block",
    "history_rows",
    "inertia_lhs",
    "mujoco_addresses",
    "pose4",
    "post_step",
    "same_or_finite",
    "set_frame",
    "stribeck_arg",
    "stribeck_level",
    "tcf_kinematics",
    "tool_wrench",
    "torques",
    "touches",
]


# ---------------------------------------------------------------- MuJoCo from compiled code

#: The MuJoCo functions the kernels call, in the order of :func:`mujoco_addresses`.
MUJOCO = ("mj_kinematics", "mj_comPos", "mj_comVel", "mj_passive", "mj_rne", "mj_jacSite",
          "mj_makeM", "mj_factorM", "mj_fullM", "mj_rnePostConstraint", "mj_objectVelocity",
          "mju_mat2Quat", "mj_solveM")
_KINEMATICS, _COM_POS, _COM_VEL, _PASSIVE, _RNE, _JAC_SITE, _MAKE_M, _FACTOR_M, _FULL_M, \
    _RNE_POST, _OBJECT_VELOCITY, _MAT2QUAT, _SOLVE_M = range(len(MUJOCO))


def mujoco_addresses() -> NDArray[np.int64]:
    """The addresses of :data:`MUJOCO`'s functions in MuJoCo's shared library: the
    kernels call MuJoCo's own functions with the world's ``mjModel`` and ``mjData``
    (their ``_address``), the same calls the Python bindings make
    (:func:`drivers.base.mjlib.function_addresses`)."""
    return function_addresses(MUJOCO)


@njit([(I1, i8, i8, F1)], cache=True)
def end_state(fns: Any, m: int, d: int, qfrc_bias: F64) -> None:
    """The end state's kinematics and bias forces: ``mj_kinematics``, ``mj_comPos``,
    ``mj_comVel``, ``mj_passive`` and ``mj_rne(m, d, 0, qfrc_bias)``, in this order."""
    c_call(fns[_KINEMATICS], (m, d))
    c_call(fns[_COM_POS], (m, d))
    c_call(fns[_COM_VEL], (m, d))
    c_call(fns[_PASSIVE], (m, d))
    c_call(fns[_RNE], (m, d, np.int32(0), qfrc_bias))


@njit([(I1, i8, i8, i8, F3, F2, F3, b1, F2)], cache=True)
def tcf_kinematics(fns: Any, m: int, d: int, site: int, jac2: F64, rot: F64, jfull2: F64,
                   make_m: bool, mfull: F64) -> None:
    """The site's Jacobian in its own frame and the full mass matrix: ``mj_jacSite`` into
    ``jac2`` (translational, rotational), ``jfull2[h] = rot^T @ jac2[h]`` (summed as
    OpenBLAS's ``dgemm``, :func:`dot3`), ``mj_makeM`` and ``mj_factorM`` if ``make_m``,
    then ``mj_fullM`` into ``mfull``."""
    c_call(fns[_JAC_SITE], (m, d, jac2[0], jac2[1], np.int32(site)))
    for h in range(2):
        for i in range(3):
            for c in range(jac2.shape[2]):
                jfull2[h, i, c] = dot3(rot[0, i], rot[1, i], rot[2, i],
                                       jac2[h, 0, c], jac2[h, 1, c], jac2[h, 2, c])
    if make_m:
        c_call(fns[_MAKE_M], (m, d))
        c_call(fns[_FACTOR_M], (m, d))
    c_call(fns[_FULL_M], (m, d, mfull))


@njit([(I1, i8, i8, i8, F3, F2, F3, b1, b1, F2, F2, F2, F2, i8, F1)], cache=True)
def inertia_lhs(fns: Any, m: int, d: int, site: int, jac2: F64, rot: F64, jfull2: F64,
                kin: bool, make_m: bool, mfull: F64, jfull: F64, minv_jt: F64, a: F64,
                va0: int, m_diag: F64) -> None:
    """``a = J M^-1 J^T`` (the inverse of the Cartesian inertia) of the TCF Jacobian
    ``jfull`` and MuJoCo's factorised mass matrix: first, with ``kin``, the Jacobian
    and mass matrix (:func:`tcf_kinematics`), else with ``make_m`` the factorisation
    (``mj_makeM``, ``mj_factorM``); then ``mj_solveM`` into ``minv_jt`` and the product
    as OpenBLAS's ``dgemm`` sums it (each of the ``nv`` products fused in turn into a
    zeroed accumulator); ``m_diag``: the arm's joint inertias (``mfull``'s diagonal from
    ``va0``)."""
    if kin:
        tcf_kinematics(fns, m, d, site, jac2, rot, jfull2, make_m, mfull)
    elif make_m:
        c_call(fns[_MAKE_M], (m, d))
        c_call(fns[_FACTOR_M], (m, d))
    c_call(fns[_SOLVE_M], (m, d, minv_jt, jfull, np.int32(6)))
    nv = jfull.shape[1]
    for i in range(6):
        for j in range(6):
            acc = 0.0
            for k in range(nv):
                acc = fma(jfull[i, k], minv_jt[j, k], acc)
            a[i, j] = acc
    for j in range(m_diag.shape[0]):
        m_diag[j] = mfull[va0 + j, va0 + j]


# ---------------------------------------------------------------- the F/T model

#: Rows of the F/T model's constants (``consts``, ``(11, 6)``): its bias, gauge range,
#: software tare, 1/resolution and resolution, then the 6x6 row-vector tool transform.
FT_BIAS, FT_RANGE, FT_TARE, FT_INV_RES, FT_RES, FT_XFORM = 0, 1, 2, 3, 4, 5


@njit([(F2, i8, F2, F2, i8, F2, i8, F2, b1, F2, B1),
       (F2, i8, F2A, F2A, i8, F2, i8, F2, b1, F2, B1)], cache=True)
def ft_block(white: F64, i: int, raw: F64, delay_buf: F64, delay_n: int, drift: F64,
             at: int, consts: F64, tared: bool, out: F64, row_over: Any) -> int:
    """One block of the Net F/T model (``FtSensorModel.process``'s arithmetic).

    With ``delay_n > 0`` the readings first go through the delay buffer ``delay_buf``
    (``[held; newest]``, ``delay_n + n`` rows): its last ``delay_n`` rows move to its
    top, ``raw`` fills the rest, and its first ``n`` rows are the block's readings
    (``x``); otherwise ``x`` is ``raw``. Then
    ``out = rint((clip?((white[i:i+n] - x) + drift[at:at+n] + bias) @ xform - tare?) *
    inv_res) * res`` for the ``n`` rows of ``raw`` (``n >= 2``: the product as
    OpenBLAS's ``dgemm`` sums it; a single row goes through ``dgemv``, whose order
    differs). The clip to the gauge range runs only when some value exceeds it (then
    ``row_over[r]`` is set per row, the number of such rows returned); the tare is
    subtracted only when ``tared``.
    """
    n = raw.shape[0]
    x = raw
    if delay_n > 0:
        for r in range(delay_n):  # forward: the source rows are below the target rows
            for c in range(6):
                delay_buf[r, c] = delay_buf[n + r, c]
        for r in range(n):
            for c in range(6):
                delay_buf[delay_n + r, c] = raw[r, c]
        x = delay_buf
    over = False
    for r in range(n):
        for c in range(6):
            v = white[i + r, c] - x[r, c]
            v += drift[at + r, c]
            v += consts[FT_BIAS, c]
            out[r, c] = v
            if abs(v) > consts[FT_RANGE, c]:
                over = True
    rows_over = 0
    if over:
        for r in range(n):
            flag = False
            for c in range(6):
                v = out[r, c]
                lim = consts[FT_RANGE, c]
                if abs(v) > lim:
                    flag = True
                # np.clip(v, -lim, lim): maximum, then minimum
                lo = -lim
                if v < lo:
                    v = lo
                if v > lim:
                    v = lim
                out[r, c] = v
            row_over[r] = flag
            if flag:
                rows_over += 1
    w = np.empty(6)
    for r in range(n):
        for c in range(6):
            w[c] = out[r, c]
        for j in range(6):
            acc = fma(w[0], consts[FT_XFORM, j], 0.0)  # BLAS's zeroed accumulator
            for k in range(1, 6):
                acc = fma(w[k], consts[FT_XFORM + k, j], acc)
            if tared:
                acc -= consts[FT_TARE, j]
            acc *= consts[FT_INV_RES, j]
            acc = np.rint(acc)
            acc *= consts[FT_RES, j]
            out[r, j] = acc
    return rows_over


@njit([(F1, i8, i8, i8, f8, F2)], cache=True)
def history_rows(history: F64, fadr: int, tadr: int, n: int, t_start: float, raw: F64) -> bool:
    """The ``n`` readings of the force and torque sensors' MuJoCo histories (each
    ``[user, cursor, times[n], values[3 n]]`` from ``fadr``, ``tadr``: a ring whose
    newest sample is at the cursor) into ``raw`` (``(n, 6)``), oldest first; ``False``
    (nothing copied) when the oldest sample's time is not ``t_start``."""
    oldest = int(history[fadr + 1]) + 1
    if oldest == n:
        oldest = 0
    if history[fadr + 2 + oldest] != t_start:
        return False
    for r in range(n):
        s = oldest + r
        if s >= n:
            s -= n
        for a in range(3):
            raw[r, a] = history[fadr + 2 + n + 3 * s + a]
            raw[r, 3 + a] = history[tadr + 2 + n + 3 * s + a]
    return True


@njit([(F2, F2), (RF2A, F2)], cache=True)
def same_or_finite(src: F64, cur: F64) -> int:
    """``0`` if the 2-D arrays ``src`` and ``cur`` (one shape) hold the same bits, else
    ``1`` if every value of ``src`` is finite, ``2`` if not (a command's latch)."""
    same = True
    for i in range(src.shape[0]):
        for j in range(src.shape[1]):
            a = src[i, j]
            b = cur[i, j]
            if not (a == b and (a != 0.0 or math.copysign(1.0, a) == math.copysign(1.0, b))):
                same = False
                break
        if not same:
            break
    if same:
        return 0
    for i in range(src.shape[0]):
        for j in range(src.shape[1]):
            if not math.isfinite(src[i, j]):
                return 2
    return 1


# ---------------------------------------------------------------- the tool's contact


@njit([(I32_2, B1), (I32_2A, B1)], cache=True)
def touches(geom: Any, is_tool: Any) -> bool:
    """Whether a contact's geom pair (``geom``: MuJoCo's ``contact.geom``, ``(ncon, 2)``)
    holds one of the tool's geoms (``is_tool[g]``; ``-1``, a flex's contact, is none)."""
    for r in range(geom.shape[0]):
        g0 = geom[r, 0]
        g1 = geom[r, 1]
        if (g0 >= 0 and is_tool[g0]) or (g1 >= 0 and is_tool[g1]):
            return True
    return False


@njit([(F1, F1, F1, F2, F1)], cache=True)
def tool_wrench(cfrc: F64, com: F64, tcp: F64, rot: F64, out: F64) -> None:
    """The tool body's external wrench ``cfrc`` (MuJoCo's ``cfrc_ext``: torque about the
    subtree centre of mass ``com``, force; world axes) at the TCP ``tcp``, in the TCF
    (``rot``: the TCP's rotation, row-major): ``out = [f @ rot, (t + r x f) @ rot]``,
    ``r = com - tcp``, the products as OpenBLAS sums them (:func:`dot3`)."""
    cx, cy, cz = cfrc[0], cfrc[1], cfrc[2]
    fx, fy, fz = cfrc[3], cfrc[4], cfrc[5]
    rx = com[0] - tcp[0]
    ry = com[1] - tcp[1]
    rz = com[2] - tcp[2]
    t0 = (cx + ry * fz) - rz * fy
    t1 = (cy + rz * fx) - rx * fz
    t2 = (cz + rx * fy) - ry * fx
    for j in range(3):
        out[j] = dot3(fx, fy, fz, rot[0, j], rot[1, j], rot[2, j])
        out[3 + j] = dot3(t0, t1, t2, rot[0, j], rot[1, j], rot[2, j])


# ---------------------------------------------------------------- the arm's state


@njit([(F1, F1, F1, F2, I1)], cache=True)
def arm_warnings(qvel: F64, q: F64, torque: F64, limits: F64, bits: Any) -> int:
    """The limit warnings of the arm's state: ``bits[0]`` if a joint's speed is beyond
    ``limits[0]`` (``|v| > limit``), ``bits[1]`` if a position is beyond ``limits[1]``
    above or ``limits[2]`` below, ``bits[2]`` if a torque reaches ``limits[3]``
    (``|tau| >= limit``)."""
    out = 0
    for j in range(q.shape[0]):
        if abs(qvel[j]) > limits[0, j]:
            out |= bits[0]
            break
    for j in range(q.shape[0]):
        if q[j] > limits[1, j] or limits[2, j] > q[j]:
            out |= bits[1]
            break
    for j in range(q.shape[0]):
        if abs(torque[j]) >= limits[3, j]:
            out |= bits[2]
            break
    return out


@njit([(F1, F1, b1, F1)], cache=True)
def stribeck_arg(speed: F64, stribeck: F64, square: bool, out: F64) -> None:
    """``-(min(|v| / v_s, 40) ** 2)`` (``square``; else the power 1) into ``out``: the
    Stribeck curve's exponent before ``exp`` (``JointFriction.apply_into``)."""
    for j in range(out.shape[0]):
        v = abs(speed[j]) / stribeck[j]
        if v > 40.0:  # np.minimum(v, 40.0) (a NaN stays)
            v = 40.0
        if square:
            v = v * v
        out[j] = -v


@njit([(F1, F1, F1, F1)], cache=True)
def stribeck_level(coulomb: F64, excess: F64, e: F64, out: F64) -> None:
    """``coulomb + excess * e`` into ``out`` (the dry level from ``e = exp(...)``)."""
    for j in range(out.shape[0]):
        out[j] = coulomb[j] + excess[j] * e[j]


@njit([(F1, F1, F2)], cache=True)
def _pose_into(pos: F64, mat9: F64, out: F64) -> None:
    """A 4x4 pose from a position and a row-major 3x3 rotation (9 values) into ``out``."""
    for i in range(3):
        for j in range(3):
            out[i, j] = mat9[3 * i + j]
        out[i, 3] = pos[i]
        out[3, i] = 0.0
    out[3, 3] = 1.0


@njit([(F1, F1)], cache=True)
def pose4(pos: F64, mat9: F64) -> F64:
    """A new 4x4 pose from a position and a row-major 3x3 rotation (9 values)."""
    out = np.empty((4, 4))
    _pose_into(pos, mat9, out)
    return out


# ---------------------------------------------------------------- a cycle's end, one call

#: MuJoCo's bad-state warnings' indices into ``mjData.warning`` (qacc, qpos, qvel) and
#: the count they are primed at (:mod:`drivers.world.divergence`).
_WARN_BAD = tuple(int(w) for w in (mujoco.mjtWarning.mjWARN_BADQACC,
                                   mujoco.mjtWarning.mjWARN_BADQPOS,
                                   mujoco.mjtWarning.mjWARN_BADQVEL))
_WARN_SEEN = 1
_OBJ_BODY = np.int32(mujoco.mjtObj.mjOBJ_BODY)
#: :func:`post_step`'s answer: the tool touches; MuJoCo flagged a bad state; a joint
#: moved beyond the inertia's reuse distance.
POST_TOUCHING, POST_DIVERGED, POST_INERTIA = 1, 2, 4


@njit([(I1, i8, i8, B1, F1, F1, F1, F2, F1, I32_1A, F1, f8, I32_2, F1, F1),
       (I1, i8, i8, B1, F1, F1, F1, F2, F1, I32_1A, F1, f8, I32_2A, F1, F1)], cache=True)
def post_step(fns: Any, m: int, d: int, is_tool: Any, cfrc: F64, com: F64, tcp: F64,
              rot: F64, qfrc_bias: F64, warn: Any, q: F64, reuse: float, geom: Any,
              contact: F64, q_ref: F64) -> int:
    """What a cycle needs after its physics steps, in the order ``SimWorld.advance``
    had it: the tool's contact (:func:`touches` on ``geom``, the contact list's geom
    pairs; touching, ``mj_rnePostConstraint`` and :func:`tool_wrench` into
    ``contact``, else zeros), the end state's dynamics (:func:`end_state`), MuJoCo's
    bad-state counters (``warn``: ``mjData.warning.number``) and whether a joint
    ``q`` moved more than ``reuse`` from ``q_ref``. Returns the ``POST_*`` bits."""
    out = 0
    if touches(geom, is_tool):
        out |= POST_TOUCHING
        c_call(fns[_RNE_POST], (m, d))
        tool_wrench(cfrc, com, tcp, rot, contact)
    else:
        for j in range(6):
            contact[j] = 0.0
    end_state(fns, m, d, qfrc_bias)
    for i in _WARN_BAD:
        if warn[i] != _WARN_SEEN:
            out |= POST_DIVERGED
    for j in range(q.shape[0]):
        if abs(q[j] - q_ref[j]) > reuse:
            out |= POST_INERTIA
            break
    return out


#: Rows of :func:`fill_state`'s pose buffer: the TCP's pose, the Cartesian set-point
#: in use, then the bodies' poses and the sites'.
POSE_TCP, POSE_CMD, POSE_BODIES = 0, 1, 2


#: :func:`fill_state`'s arrays, by their addresses (``arrays``; each C-contiguous and
#: kept where it is for the world's life), and its sizes and ids (``dims``).
FILL_ARRAYS = ("qpos", "qvel", "torque", "gravcomp", "site_xpos", "site_xmat", "xpos",
               "xmat", "jac2", "jfull2", "mfull", "work", "limits")
FILL_DIMS = ("n", "nv", "nsite", "nbody", "tcp_site", "va0", "bodies", "sites", "bit0",
             "bit1", "bit2")


def _f64_ptr_typing(typingctx: Any, addr: Any) -> Any:
    """The ``double*`` at the address ``addr`` (an ``int64``)."""
    pointer: Any = types.CPointer  # (numba's types are untyped)
    sig = pointer(types.float64)(types.int64)

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        return builder.inttoptr(args[0], context.get_value_type(signature.return_type))

    return sig, codegen


#: ``_f64_ptr(addr)`` in compiled code: a float64 array's data at ``addr``, for ``carray``.
_f64_ptr: Any = intrinsic(_f64_ptr_typing)


@njit([(I1, i8, i8, I1, I1, b1, b1, RF1, b1, RF2, RF2, RF1, F3, F3)], cache=True)
def fill_state(fns: Any, m: int, d: int, arrays: Any, dims: Any, kin: bool, make_m: bool,
               jnt_src: F64, cart: bool, cart_src: F64, tcp_src: F64, contact: F64,
               mats: F64, poses: F64) -> int:
    """An arm state's arrays at the end state, into ``mats`` and ``poses``; returns its
    limit warnings (:func:`arm_warnings`).

    ``arrays``: the addresses of :data:`FILL_ARRAYS` (the arm's joints, speeds,
    actuator torques and gravity torques; MuJoCo's site and body positions and
    rotations; the Jacobian and mass matrix work arrays; a 6-array; the limits);
    ``dims``: :data:`FILL_DIMS`, then the bodies' ids and the sites' (passed by
    address, they cost the call nothing). ``mats`` (``(3 + bodies, L, L)``,
    ``L = max(n, 6)`` for ``n`` joints): the mass matrix in ``[0, :n, :n]``, the TCF
    Jacobian in ``[1, :6, :n]``; in ``[2]``'s rows the joints, the joint set-point in
    use (``jnt_src``), the gravity torques (``n`` values each) and the contact wrench
    (a copy of ``contact``); each body's twist ``[v, w]`` (``mj_objectVelocity``, world
    axes) in ``[3 + k, 0, :6]``. ``poses``: the TCP's 4x4 (from its site, or a copy of
    ``tcp_src`` when that is 4x4), the Cartesian set-point in use (``cart_src`` if
    ``cart``, else the TCP's), each body's, each site's. With ``kin`` the Jacobian and
    mass matrix are computed first (:func:`tcf_kinematics`, the mass matrix factorised
    too if ``make_m``); else the work arrays hold them."""
    n, nv, nsite, nbody, tcp_site, va0, nb, ns = (dims[0], dims[1], dims[2], dims[3],
                                                   dims[4], dims[5], dims[6], dims[7])
    qpos = carray(_f64_ptr(arrays[0]), (n,))
    qvel = carray(_f64_ptr(arrays[1]), (n,))
    torque = carray(_f64_ptr(arrays[2]), (n,))
    gravcomp = carray(_f64_ptr(arrays[3]), (n,))
    site_xpos = carray(_f64_ptr(arrays[4]), (nsite, 3))
    site_xmat = carray(_f64_ptr(arrays[5]), (nsite, 9))
    xpos = carray(_f64_ptr(arrays[6]), (nbody, 3))
    xmat = carray(_f64_ptr(arrays[7]), (nbody, 9))
    jac2 = carray(_f64_ptr(arrays[8]), (2, 3, nv))
    jfull2 = carray(_f64_ptr(arrays[9]), (2, 3, nv))
    mfull = carray(_f64_ptr(arrays[10]), (nv, nv))
    work = carray(_f64_ptr(arrays[11]), (6,))
    limits = carray(_f64_ptr(arrays[12]), (4, n))
    bits = dims[8:11]
    body_ids = dims[11:11 + nb]
    site_ids = dims[11 + nb:11 + nb + ns]
    n = qpos.shape[0]
    for j in range(n):
        mats[2, 0, j] = qpos[j]
        mats[2, 1, j] = qpos[j] if cart else jnt_src[j]
        mats[2, 2, j] = gravcomp[j]
    for j in range(6):
        mats[2, 3, j] = contact[j]
    if tcp_src.shape[0] == 4:
        for i in range(4):
            for j in range(4):
                poses[POSE_TCP, i, j] = tcp_src[i, j]
    else:
        _pose_into(site_xpos[tcp_site], site_xmat[tcp_site], poses[POSE_TCP])
    for i in range(4):
        for j in range(4):
            poses[POSE_CMD, i, j] = cart_src[i, j] if cart else poses[POSE_TCP, i, j]
    if kin:
        tcf_kinematics(fns, m, d, tcp_site, jac2, site_xmat[tcp_site].reshape((3, 3)),
                       jfull2, make_m, mfull)
    for r in range(2):
        for i in range(3):
            for j in range(n):
                mats[1, 3 * r + i, j] = jfull2[r, i, va0 + j]
    for i in range(n):
        for j in range(n):
            mats[0, i, j] = mfull[va0 + i, va0 + j]
    for k in range(body_ids.shape[0]):
        b = body_ids[k]
        _pose_into(xpos[b], xmat[b], poses[POSE_BODIES + k])
        c_call(fns[_OBJECT_VELOCITY], (m, d, _OBJ_BODY, np.int32(b), work, np.int32(0)))
        for j in range(3):  # MuJoCo's [w, v] as [v, w]
            mats[3 + k, 0, j] = work[3 + j]
            mats[3 + k, 0, 3 + j] = work[j]
    first = POSE_BODIES + body_ids.shape[0]
    for k in range(site_ids.shape[0]):
        s = site_ids[k]
        _pose_into(site_xpos[s], site_xmat[s], poses[first + k])
    return arm_warnings(qvel, mats[2, 0, :n], torque, limits, bits)


@njit([(F1, F1, F1)], cache=True)
def torques(tau: F64, bias: F64, tau_ext: F64) -> None:
    """``tau += bias; tau -= tau_ext`` (the link-side torque sensors from ``M qdd``)."""
    for j in range(tau.shape[0]):
        tau[j] = (tau[j] + bias[j]) - tau_ext[j]


@njit([(I1, F2, F1, F1, F1), (I1, RF2A, F1, F1, F1)], cache=True)
def set_frame(fns: Any, pose: F64, pos: F64, quat: F64, work: F64) -> None:
    """A 4x4 pose into a frame's position ``pos`` and unit quaternion ``quat``
    (``mju_mat2Quat`` of its rotation, copied row-major into the 9 values ``work``)."""
    for i in range(3):
        pos[i] = pose[i, 3]
        for j in range(3):
            work[3 * i + j] = pose[i, j]
    c_call(fns[_MAT2QUAT], (quat, work))

