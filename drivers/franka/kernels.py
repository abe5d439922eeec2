"""The driver's arm kinematics, compiled (numba): the TCP's Jacobian in the TCF and the TCP's
pose in one call per state. Pure maths: no I/O.

Imported when a :class:`~drivers.franka.model.ArmModel` is made (numba's import costs
about 0.4 s; ``ffexp --help`` never imports it); cached on disk next to this module.

Bit for bit the numbers of the numpy form (:meth:`ArmModel.jacobian_tcf_numpy
<drivers.franka.model.ArmModel.jacobian_tcf_numpy>`): the same IEEE operations in the same
order, no fast-math. The numpy form's matrix products go through BLAS; OpenBLAS's
``dgemm`` (3x3 and 4x4 products, the transposed rotation times the Jacobian's rows)
fuses the products of a sum into ``+0.0`` in turn (:func:`_dot`), its ``dgemv`` of a
rotation (a slice of a pose) and an axis as :func:`~drivers.base.blas.dot3_n`.
``tests/test_franka_kernels.py`` checks the whole against the numpy form on random
joints and tools, and the sums against numpy's own products.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from drivers.base.blas import dot3_n, fma
from drivers.base.signatures import F2, F2A, F3, I2, RF1A, RF2A
from drivers.base.types import F64


@njit([(RF2A, RF2A, F2A)], cache=True)
def _matmul(a: F64, b: F64, out: F64) -> None:
    """``out = a @ b`` as OpenBLAS's ``dgemm``: each sum fused in turn into ``+0.0``
    (``out`` may not be ``a`` or ``b``)."""
    n, k = a.shape
    m = b.shape[1]
    for i in range(n):
        for j in range(m):
            acc = 0.0
            for s in range(k):
                acc = fma(a[i, s], b[s, j], acc)
            out[i, j] = acc


@njit([(RF1A, F3, F2, I2, F2, RF2A, F2, F2)], cache=True)
def tcf_jacobian(q: F64, turns: F64, origins: F64, axes: np.ndarray, flange: F64,
                 flange_to_tcp: F64, jac: F64, tcp: F64) -> None:
    """The 6xn Jacobian (TCF rows) into ``jac`` and the TCP's pose into ``tcp``.

    ``turns`` (n, 3, 3): each joint frame's fixed rotation; ``origins`` (n, 3): its
    origin in its parent; ``axes`` (n, 3) ints: its signed unit axis; ``flange``: the
    flange in the last link (4x4); ``flange_to_tcp``: the tool (4x4)."""
    n = q.shape[0]
    rot = np.empty((3, 3))
    t = np.empty((4, 4))
    pose = np.eye(4)
    nxt = np.empty((4, 4))
    frames = np.empty((n, 4, 4))
    for i in range(n):
        # ArmDescription.joint_transforms: the axis rotation, turned, at the origin
        k = 0
        for c in range(3):
            if axes[i, c] != 0:
                k = c
        angle = q[i]
        co = math.cos(angle)
        si = math.sin(angle) * axes[i, k]
        rot[:] = 0.0
        rot[0, 0] = rot[1, 1] = rot[2, 2] = 1.0
        a, b = (k + 1) % 3, (k + 2) % 3
        rot[a, a], rot[a, b], rot[b, a], rot[b, b] = co, -si, si, co
        t[:] = 0.0
        t[3, 3] = 1.0
        _matmul(turns[i], rot, t[:3, :3])
        for c in range(3):
            t[c, 3] = origins[i, c]
        _matmul(pose, t, nxt)
        pose[:] = nxt
        frames[i] = pose
    _matmul(pose, flange, nxt)
    _matmul(nxt, flange_to_tcp, tcp)
    px, py, pz = tcp[0, 3], tcp[1, 3], tcp[2, 3]
    cols = np.empty((6, n))
    for i in range(n):
        f = frames[i]
        a0, a1, a2 = float(axes[i, 0]), float(axes[i, 1]), float(axes[i, 2])
        z0 = dot3_n(f[0, 0], f[0, 1], f[0, 2], a0, a1, a2)
        z1 = dot3_n(f[1, 0], f[1, 1], f[1, 2], a0, a1, a2)
        z2 = dot3_n(f[2, 0], f[2, 1], f[2, 2], a0, a1, a2)
        d0, d1, d2 = px - f[0, 3], py - f[1, 3], pz - f[2, 3]
        cols[0, i] = z1 * d2 - z2 * d1  # drivers.carrier.body.cross3
        cols[1, i] = z2 * d0 - z0 * d2
        cols[2, i] = z0 * d1 - z1 * d0
        cols[3, i], cols[4, i], cols[5, i] = z0, z1, z2
    r_t = tcp[:3, :3].T
    _matmul(r_t, cols[:3], jac[:3])
    _matmul(r_t, cols[3:], jac[3:])
