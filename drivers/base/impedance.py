"""The KRC's impedance controllers as FRI exposes them: pure maths, no I/O.

Cartesian impedance (FRI strategy 20, the paper's eq. for tau_cmd)::

    tau = J^T (K (x_cmd - x_msr) - D xdot + F_cmd) + f_dyn(q, qdot)

with K per TCF axis, the normalised damping d in [0, 1] turned into
``D_i = 2 d_i sqrt(K_i Lambda_ii)`` from the Cartesian inertia
``Lambda = (J M^-1 J^T)^-1`` (a per-axis damping ratio, which is what
"normalized" means in friComm), and f_dyn = gravity + Coriolis.
Joint impedance (strategy 30) is the same per joint with
``D_j = 2 d_j sqrt(k_j M_jj)``; joint position mode (10) is joint impedance at
a fixed high stiffness.

:class:`~drivers.world.world.SimWorld` realises these laws with MuJoCo
actuators so they run inside every physics step; these functions are the
reference the tests compare against, and what the world uses to compute the
gains once per FRI cycle.
"""

from __future__ import annotations

import numpy as np

from drivers.base.types import F64


def cartesian_inertia(jac: F64, mass: F64) -> F64:
    """Lambda = (J M^-1 J^T)^-1 for a 6xn Jacobian and nxn mass matrix."""
    minv_jt = np.linalg.solve(mass, jac.T)
    return np.asarray(np.linalg.inv(jac @ minv_jt), dtype=np.float64)


def cartesian_mobility(jac: F64, mass: F64) -> F64:
    """J M^-1 J^T: the TCP acceleration per unit wrench (inverse of Lambda)."""
    return np.asarray(jac @ np.linalg.solve(mass, jac.T), dtype=np.float64)


def normalized_damping(stiffness: F64, damping: F64, inertia_diag: F64) -> F64:
    """``D_i = 2 d_i sqrt(K_i m_i)``: damping ratio d_i of axis i with stiffness K_i."""
    return np.asarray(
        2.0 * damping * np.sqrt(np.maximum(stiffness, 0.0) * np.maximum(inertia_diag, 0.0)),
        dtype=np.float64,
    )


def clip_cart_stiffness(stiffness: F64, max_lin: float, max_rot: float) -> tuple[F64, bool]:
    """Clip ``[x, y, z, rx, ry, rz]`` stiffness into ``[0, max]``; report whether it clipped."""
    hi = np.array([max_lin] * 3 + [max_rot] * 3)
    out = np.clip(stiffness, 0.0, hi)
    return out, bool(np.any(out != stiffness))


def rotation_error(r_cmd: F64, r_msr: F64) -> F64:
    """Rotation vector taking ``r_msr`` to ``r_cmd``, in the ``r_msr`` frame."""
    rel = r_msr.T @ r_cmd
    cos = np.clip((np.trace(rel) - 1.0) / 2.0, -1.0, 1.0)
    angle = float(np.arccos(cos))
    axis = np.array([rel[2, 1] - rel[1, 2], rel[0, 2] - rel[2, 0], rel[1, 0] - rel[0, 1]])
    if angle < 1e-9:
        return np.asarray(axis / 2.0, dtype=np.float64)
    return np.asarray(axis * (angle / (2.0 * np.sin(angle))), dtype=np.float64)


def cart_impedance_torque(
    jac: F64,
    pose_cmd: F64,
    pose_msr: F64,
    twist: F64,
    stiffness: F64,
    damping: F64,
    wrench_cmd: F64,
    f_dyn: F64,
) -> F64:
    """tau = J^T (K e - D xdot + F_cmd) + f_dyn, all Cartesian terms in the TCF.

    ``jac`` maps qdot to the TCF twist ``[v, w]``; ``damping`` is the
    dimensional D (see :func:`normalized_damping`).
    """
    r = pose_msr[:3, :3]
    err = np.empty(6)
    err[:3] = r.T @ (pose_cmd[:3, 3] - pose_msr[:3, 3])
    err[3:] = rotation_error(pose_cmd[:3, :3], r)
    f = stiffness * err - damping * twist + wrench_cmd
    return np.asarray(jac.T @ f + f_dyn, dtype=np.float64)
