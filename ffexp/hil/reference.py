"""The one-dimensional delayed unilateral contact, the reference a rendered impact is
judged by: a free mass ``m`` hits a contact of stiffness ``k`` and damping ``c`` whose
force reaches it ``tau`` late,

    m x''(t) = -F(t - tau),   F = max(0, k x + c x') while x > 0, else 0,

``x`` the penetration (the mass arrives at ``x = 0`` with ``x' = v0 > 0``).
:func:`delayed_restitution` solves it with scipy's Runge-Kutta stepper, the delayed
force taken from the accepted steps' dense solution; the closed forms beside it are the linear one
(:func:`linear_restitution`, ``exp(-pi z' / sqrt(1 - z'^2))``, ``z' = z - w tau / 2``,
which drifts from the unilateral contact at high damping) and the bilateral contact's
critical delay (:func:`critical_delay`). Source of the formulas:
``docs/hil.md``. Pure maths, no I/O.
"""

from __future__ import annotations

import bisect
import math

import numpy as np
from scipy.integrate import RK45, DenseOutput

__all__ = ["critical_delay", "delayed_restitution", "linear_restitution"]

#: Longest contact the solver follows, in undamped periods (a contact that has not
#: ended by then: None).
MAX_PERIODS = 50.0


def linear_restitution(damping_ratio: float, wn_tau: float) -> float:
    """The linear closed form: the delay as negative damping ``k tau``."""
    z = damping_ratio - wn_tau / 2.0
    if z <= -1.0:
        return math.inf
    if z >= 1.0:
        return 0.0
    return math.exp(-math.pi * z / math.sqrt(1.0 - z * z))


def critical_delay(mass_kg: float, stiffness_npm: float, damping_nspm: float) -> float:
    """The bilateral contact's critical delay [s]: ``m s^2 + (c s + k) e^{-s tau} = 0`` has a
    root on the imaginary axis at ``w_c^2 = (c^2 + sqrt(c^4 + 4 m^2 k^2)) / (2 m^2)``,
    ``tau_c = atan2(c w_c, k) / w_c`` (about ``c / k``)."""
    m, k, c = mass_kg, stiffness_npm, damping_nspm
    wc = math.sqrt((c * c + math.sqrt(c ** 4 + 4.0 * m * m * k * k)) / (2.0 * m * m))
    return math.atan2(c * wc, k) / wc


def delayed_restitution(mass_kg: float, stiffness_npm: float, damping_nspm: float,
                        delay_s: float, speed_mps: float = 1.0) -> float | None:
    """``-x'(end) / v0`` of the delayed unilateral contact (``None``: still in contact
    after :data:`MAX_PERIODS` periods). The result does not depend on ``speed_mps``
    (the equation is linear in each of its pieces and homogeneous).

    Solved step by step with scipy's ``RK45`` (tolerance 1e-10, at most 1/400 of a
    period per step): the delayed state comes from the accepted steps' dense output;
    when the delay is shorter than the step being taken it falls inside that step, and
    the last accepted step's polynomial is extended to it (an error of the step's order).
    """
    m, k, c, tau = mass_kg, stiffness_npm, damping_nspm, max(0.0, delay_s)
    period = 2.0 * math.pi / math.sqrt(k / m)

    def force(x: float, v: float) -> float:
        return max(0.0, k * x + c * v) if x > 0.0 else 0.0

    ends: list[float] = []
    dense: list[DenseOutput] = []

    def delayed(t: float, y: np.ndarray) -> float:
        if tau == 0.0:
            return force(float(y[0]), float(y[1]))
        s = t - tau
        if s < 0.0:
            return 0.0  # before the touch: no contact
        i = min(bisect.bisect_left(ends, s), len(ends) - 1)
        x, v = dense[i](s) if dense else (0.0, speed_mps)
        return force(float(x), float(v))

    solver = RK45(lambda t, y: np.array([y[1], -delayed(t, y) / m]), 0.0,
                  np.array([0.0, speed_mps]), MAX_PERIODS * period, rtol=1e-10,
                  atol=1e-13 * max(speed_mps, 1.0) * period, max_step=period / 400.0)
    last_push = 0.0
    while solver.status == "running":
        solver.step()
        ends.append(solver.t)
        dense.append(solver.dense_output())
        x, v = float(solver.y[0]), float(solver.y[1])
        if force(x, v) > 0.0:
            last_push = solver.t
        elif x < 0.0 and v < 0.0 and solver.t > last_push + tau and len(ends) > 1 and (
                float(dense[-1](solver.t_old)[0]) < 0.0):
            return -v / speed_mps  # left the contact and no force is on its way
        if len(ends) > 4096:  # keep the history the delay needs
            keep = bisect.bisect_left(ends, solver.t - tau - period) - 1
            if keep > 0:
                del ends[:keep], dense[:keep]
    return None
