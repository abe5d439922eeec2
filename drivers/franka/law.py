"""The driver's 1 kHz law: Cartesian impedance with the wrench feed-forward, in joint torques.

What the KRC does inside for the LWR4+ (:mod:`drivers.base.impedance`), here in the
driver because libfranka hands the client the torque loop::

    tau = J^T (K e - D v + F_cmd) + N (k_null (q_null - q) - d_null qdot),
    D_i = 2 d_i sqrt(K_i Lambda_ii)

with ``e`` the pose error and ``v`` the TCP's twist in the TCF, the normalised damping
``d`` against the Cartesian inertia ``Lambda = (J M^-1 J^T)^-1`` (recomputed when a joint
moved more than :data:`INERTIA_REUSE_RAD` since), and ``N = I - J^T (J^+)^T`` the null
space of the task, where a joint spring towards the pose the arm had when the loop began
(``q_null``) and a joint damping hold the redundant elbow (as Franka's own Cartesian
impedance example does; without them the elbow drifts under the contact's wrench). Gravity is the
robot's (libfranka's torques exclude it); Coriolis terms are not compensated (slow
motions). The torque is clipped to the joints' limits and to the FR3's torque rate
(1000 N m/s: at most 1 N m per cycle), as libfranka's rate limiter would.

Per cycle only what changed is computed anew: the clipped stiffness and the damping
while the set-point's stiffness, damping ratios and the Cartesian inertia are the same
(ffexp's loop sets a new set-point every few cycles), and the null space's
pseudo-inverse through numpy's own LAPACK call (:func:`pinv`, numpy's
``np.linalg.pinv`` without its wrapper's checks: the same numbers).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from drivers.base.impedance import (
    cart_impedance_torque,
    cartesian_inertia,
    clip_cart_stiffness,
    normalized_damping,
)
from drivers.base.types import F64, CartesianCommand
from drivers.description.fr3 import TORQUE_LIMITS_NM, TORQUE_RATE_LIMIT_NMPS
from drivers.franka.model import ArmModel

__all__ = ["INERTIA_REUSE_RAD", "ImpedanceLaw", "pinv"]

#: The Cartesian inertia is reused while no joint moved further than this [rad].
INERTIA_REUSE_RAD = 0.005

_svd: Callable[..., tuple[F64, F64, F64]] | None = getattr(
    getattr(np.linalg, "_umath_linalg", None), "svd_s", None)


def pinv(a: F64) -> F64:
    """``np.linalg.pinv(a)`` of a real matrix (its default cut-off, ``1e-15`` of the
    largest singular value): the same LAPACK call and the same operations after it,
    without the wrapper's checks; an SVD that does not converge (NaN) goes to
    ``np.linalg.pinv`` itself, which raises."""
    if _svd is None:  # (a numpy without the gufunc)
        return np.asarray(np.linalg.pinv(a), dtype=np.float64)
    u, s, vt = _svd(a, signature="d->ddd")
    top = s.max()
    if top != top:
        return np.asarray(np.linalg.pinv(a), dtype=np.float64)
    large = s > 1e-15 * top
    s = np.divide(1, s, where=large, out=s)
    s[~large] = 0
    return np.asarray(np.matmul(vt.T, np.multiply(s[:, np.newaxis], u.T)), dtype=np.float64)


class ImpedanceLaw:
    """The law for one arm at ``cycle_s`` (module docstring)."""

    def __init__(self, model: ArmModel, *, stiffness_max: tuple[float, float],
                 nullspace_damping: float, nullspace_stiffness: float = 0.0,
                 cycle_s: float = 0.001,
                 torque_limits: tuple[float, ...] = TORQUE_LIMITS_NM,
                 torque_rate_nmps: float = TORQUE_RATE_LIMIT_NMPS) -> None:
        self.model = model
        self.stiffness_max = stiffness_max
        self.nullspace_damping = nullspace_damping
        self.nullspace_stiffness = nullspace_stiffness
        self.q_null: F64 | None = None
        """The joints the null-space spring pulls to (set by the first cycle)."""
        self._limits = np.asarray(torque_limits, dtype=np.float64)
        self._step = torque_rate_nmps * cycle_s
        self._last_tau: F64 | None = None
        self._q_lambda: F64 | None = None
        self._lam_diag = np.zeros(6)
        self._eye = np.eye(len(self._limits))
        self._zeros = np.zeros(len(self._limits))
        # the stiffness and damping of the last set-point: (stiffness, ratios, lam) -> (k, d)
        self._gains_of: tuple[bytes, bytes, F64] | None = None
        self._gains: tuple[F64, F64] = (np.zeros(6), np.zeros(6))
        self.clipped = False
        """The last command's stiffness was beyond :attr:`stiffness_max` and was clipped."""

    def torque(self, q: F64, dq: F64, pose_msr: F64, flange_to_tcp: F64,
               setpoint: CartesianCommand) -> F64:
        """The joint torques for one cycle (gravity excluded), towards ``setpoint``."""
        jac, _tcp = self.model.jacobian_tcf(q, flange_to_tcp)
        if self._q_lambda is None or np.max(np.abs(q - self._q_lambda)) > INERTIA_REUSE_RAD:
            lam = cartesian_inertia(jac, self.model.mass_matrix(q))
            self._lam_diag = lam.diagonal().copy()
            self._q_lambda = q.copy()
        stiffness = np.asarray(setpoint.stiffness_npm_nmprad)
        ratios = np.asarray(setpoint.damping_ratio)
        key = (stiffness.tobytes(), ratios.tobytes(), self._lam_diag)
        of = self._gains_of
        if of is None or of[2] is not key[2] or of[0] != key[0] or of[1] != key[1]:
            k, self.clipped = clip_cart_stiffness(stiffness, *self.stiffness_max)
            self._gains = (k, normalized_damping(k, ratios, self._lam_diag))
            self._gains_of = key
        k, d = self._gains
        twist = jac @ dq
        tau = cart_impedance_torque(jac, np.asarray(setpoint.pose_m), pose_msr, twist, k, d,
                                    np.asarray(setpoint.wrench_n_nm), self._zeros)
        if self.q_null is None:
            self.q_null = q.copy()
        if self.nullspace_damping > 0.0 or self.nullspace_stiffness > 0.0:
            null = self._eye - jac.T @ pinv(jac.T)
            tau = tau + null @ (self.nullspace_stiffness * (self.q_null - q)
                                - self.nullspace_damping * dq)
        tau = np.clip(tau, -self._limits, self._limits)
        if self._last_tau is not None:
            tau = np.clip(tau, self._last_tau - self._step, self._last_tau + self._step)
        self._last_tau = tau
        return np.asarray(tau, dtype=np.float64)

    def reset(self) -> None:
        """Forget the last torque (a new torque loop starts from zero)."""
        self._last_tau = np.zeros(len(self._limits))
        self.q_null = None
