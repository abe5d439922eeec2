"""What a contact's restitution means for its damping: the coefficient of restitution
of a linear spring-damper contact that only pushes (:func:`restitution_of`) and its
inverse (:func:`damping_ratio_for`). The simulator's funnel contact
(:mod:`drivers.world.contact`) and the carrier's impact bench (:mod:`drivers.carrier`)
both derive a contact's damping from the scene's ``contact.restitution`` with them.
Pure maths, no I/O.
"""

from __future__ import annotations

import math

from scipy.optimize import brentq

__all__ = ["DAMPING_RATIO_RANGE", "damping_ratio_for", "restitution_of"]


def _unit_impact(z: float, t: float) -> tuple[float, float]:
    """Penetration and its rate at time ``t`` of a unit-frequency spring-damper of
    damping ratio ``z`` that touched at unit speed (closed forms per regime)."""
    if z < 1.0:
        w = math.sqrt(1.0 - z * z)
        e, s, c = math.exp(-z * t), math.sin(w * t), math.cos(w * t)
        return e * s / w, e * (c - z * s / w)
    if z == 1.0:
        e = math.exp(-t)
        return t * e, (1.0 - t) * e
    r = math.sqrt(z * z - 1.0)
    e1, e2 = math.exp((-z + r) * t), math.exp((-z - r) * t)
    return (e1 - e2) / (2.0 * r), ((-z + r) * e1 - (-z - r) * e2) / (2.0 * r)


def restitution_of(damping_ratio: float) -> float:
    """The coefficient of restitution of a linear spring-damper contact that only
    pushes (its force clamped at zero, as a contact's): an impact at relative
    normal speed v leaves at e v.

    The force ``k x + c x'`` returns to zero before the spring is relaxed, and the
    bodies separate with the speed they have then, so ``e`` is above the
    unclamped oscillator's ``exp(-z pi / sqrt(1 - z^2))`` and stays above zero
    at any damping (critical damping: ``exp(-2) = 0.135``).
    """
    z = float(damping_ratio)
    if z <= 0.0:
        return 1.0

    def force(t: float) -> float:  # over k: x + 2 z x' in units of the frequency
        x, v = _unit_impact(z, t)
        return x + 2.0 * z * v

    t_hi = math.pi
    while force(t_hi) >= 0.0:  # positive at 0+, negative once the damper pulls
        t_hi *= 2.0
    t = brentq(force, 1e-12, t_hi, xtol=1e-14, rtol=1e-14)
    return -_unit_impact(z, t)[1]


#: Damping ratios :func:`damping_ratio_for` searches (restitution 1 - 3e-6 to 0.0005).
DAMPING_RATIO_RANGE = (1e-6, 1e3)


def damping_ratio_for(restitution: float) -> float:
    """The damping ratio whose clamped contact rebounds with ``restitution`` (the
    inverse of :func:`restitution_of`, which falls monotonically with the ratio).

    Raises:
        ValueError: ``restitution`` outside what :data:`DAMPING_RATIO_RANGE` gives.
    """
    e = float(restitution)
    lo, hi = DAMPING_RATIO_RANGE
    e_hi, e_lo = restitution_of(lo), restitution_of(hi)
    if not e_lo <= e <= e_hi:
        raise ValueError(f"restitution must be in [{e_lo:.2g}, {e_hi:.6g}], got {e:g}")
    return float(math.exp(brentq(lambda lz: restitution_of(math.exp(lz)) - e,
                                 math.log(lo), math.log(hi), xtol=1e-13)))
