"""What a rendered-target impact's recording says (``ffexp analyze --json`` on it): the
apparent coefficient of restitution, the loop's delay as measured, the contact's
numbers, the target's true restitution (the same impact on the free body), the
delayed unilateral contact's prediction (:mod:`ffexp.hil.reference`), and what the
compensation cost. Pure maths on the recording's arrays.

- ``restitution``: the closing speed at the contact point after the impact over the
  one before, of the rendered body (``None`` when the carrier held before the contact
  ended: ``carrier_held`` says why).
- ``loop_delay_s``: the lag that best maps the contact's impulse onto the mock-up's
  motion, ``m (w(t) - w(0)) = J(t - tau)`` (``w`` the mock-up's normal velocity at the
  contact point, ``J`` the contact force's integral, ``m`` the effective mass): the
  whole loop, F/T sensor to the carrier's response, measured.
- ``path_error_m``: the largest distance between the flange's path and the ideal free
  body's over the run; ``dissipated_j``: what the passivity controller took out;
  the contact's duration and peak force beside the free body's (a virtual compliance
  makes the contact longer and softer).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.optimize import minimize_scalar

from drivers.base.types import F64
from ffexp.errors import InputError
from ffexp.hil.reference import critical_delay, delayed_restitution, linear_restitution
from ffexp.recording.reader import Recording

__all__ = ["analyze_recording", "is_hil", "measure_delay", "restitution_from"]

#: Longest loop delay the fit looks for [s].
MAX_DELAY_S = 0.1
#: A contact force below this is no contact [N] (the truth has no noise).
CONTACT_N = 1e-9


def is_hil(rec: Recording) -> bool:
    """Whether the recording is a rendered-target impact."""
    from ffexp.hil.record import HIL_METADATA

    return HIL_METADATA in rec.metadata


def restitution_from(t_s: F64, closing: F64, contact_start_s: float,
                     contact_end_s: float | None, settle_s: float = 0.0) -> float | None:
    """``-closing(after) / closing(before)``: before is the last sample at or before the
    contact's start, after the first one ``settle_s`` (the force still on its way
    through the loop) past the contact's end (a body the impact set turning moves its
    contact point on: later samples would see that, not the impact)."""
    before = np.flatnonzero(t_s <= contact_start_s + 1e-12)
    if contact_end_s is None or before.size == 0:
        return None
    after = np.flatnonzero(t_s >= contact_end_s + settle_s - 1e-12)
    if not after.size:
        return None
    v0 = float(closing[before[-1]])
    return -float(closing[after[0]]) / v0 if v0 > 0.0 else None


def measure_delay(t_s: F64, force_n: F64, normal_mps: F64, mass_kg: float) -> float:
    """The loop's delay: the ``tau`` that best fits ``m (w - w0) = J(t - tau)`` (least
    squares over the samples given, which start at the contact)."""
    dt = np.diff(t_s)
    impulse = np.concatenate(([0.0], np.cumsum(0.5 * (force_n[1:] + force_n[:-1]) * dt)))
    momentum = mass_kg * (normal_mps - normal_mps[0])

    def misfit(tau: float) -> float:
        shifted = np.interp(t_s - tau, t_s, impulse, left=0.0)
        return float(np.mean((momentum - shifted) ** 2))

    step = float(np.median(dt))
    top = min(MAX_DELAY_S, float(t_s[-1] - t_s[0]) / 2.0)
    grid = np.arange(0.0, top, step)
    best = float(grid[int(np.argmin([misfit(x) for x in grid]))])
    res = minimize_scalar(misfit, bounds=(max(0.0, best - step), best + step),
                          method="bounded", options={"xatol": step * 1e-3})
    return float(res.x)


def analyze_recording(rec: Recording) -> dict[str, Any]:
    """The impact's numbers (see the module)."""
    from ffexp.hil.record import HIL_METADATA

    meta = rec.metadata[HIL_METADATA]
    try:
        state, ideal, contact = (rec.topic(n) for n in ("/carrier/state", "/hil/ideal",
                                                         "/hil/contact"))
    except KeyError as exc:
        raise InputError(f"{rec.path}: a rendered-target recording without {exc}") from None
    m, k, c = (float(meta[key]) for key in ("effective_mass_kg", "contact_stiffness_npm",
                                             "contact_damping_nspm"))
    t_fine = (contact.log_time_ns - contact.log_time_ns[0]) / 1e9 if len(contact) else np.zeros(0)
    force = contact["force_n"]
    touching = np.flatnonzero(force > CONTACT_N)
    events = rec.json.get("/carrier/event")
    held, held_s = None, math.inf
    if events is not None and len(events):
        first = events.messages[0]
        held, held_s = f"{first['device']}: {first['cause']}", float(first["t_s"])
    out: dict[str, Any] = {
        "restitution": None, "true_restitution": None, "reference_restitution": None,
        "linear_restitution": None, "loop_delay_s": None,
        "critical_delay_s": critical_delay(m, k, c),
        "effective_mass_kg": m, "contact_stiffness_npm": k, "contact_damping_nspm": c,
        "compensation": meta["compensation"],
        "extra_delay_cycles": int(meta["extra_delay_cycles"]),
        "carrier_cycle_s": float(meta["carrier_cycle_s"]),
        "dissipated_j": float(state["dissipated_j"][-1]) if len(state) else 0.0,
        "generated_j": float(state["generated_j"][-1]) if len(state) else 0.0,
        "path_error_m": None, "carrier_held": held, "contact": bool(touching.size),
        "contact_duration_s": None, "true_contact_duration_s": None,
        "peak_force_n": float(np.max(force)) if len(force) else 0.0,
        "true_peak_force_n": float(np.max(np.linalg.norm(ideal["wrench_measured"][:, :3],
                                                          axis=1))) if len(ideal)
        else 0.0,
    }
    if not touching.size:
        return out
    start, last = float(t_fine[touching[0]]), float(t_fine[touching[-1]])
    end = None if touching[-1] + 1 >= len(force) else float(t_fine[touching[-1] + 1])
    t_state = (state.log_time_ns - contact.log_time_ns[0]) / 1e9
    t_ideal = (ideal.log_time_ns - contact.log_time_ns[0]) / 1e9
    ideal_touch = np.flatnonzero(np.linalg.norm(ideal["wrench_measured"][:, :3], axis=1)
                                 > CONTACT_N)
    ideal_force_end = (float(t_ideal[ideal_touch[-1] + 1])
                       if ideal_touch.size and ideal_touch[-1] + 1 < len(t_ideal) else None)
    if ideal_touch.size and ideal_force_end is not None:
        out["true_contact_duration_s"] = ideal_force_end - float(t_ideal[ideal_touch[0]])
    if end is not None:
        out["contact_duration_s"] = end - start
    stop = min(float(t_state[-1]), held_s)
    window = (t_fine >= start) & (t_fine <= min(last + 0.05, stop))
    if np.count_nonzero(window) > 4:
        tau = measure_delay(t_fine[window], force[window],
                            contact["normal_velocity_mps"][window], m)
        out["loop_delay_s"] = tau
        z = c / (2.0 * math.sqrt(k * m))
        out["reference_restitution"] = delayed_restitution(m, k, c, tau)
        out["linear_restitution"] = linear_restitution(z, math.sqrt(k / m) * tau)
    if held is None:
        settle = (out["loop_delay_s"] or 0.0) + 2.0 * float(meta["carrier_cycle_s"])
        out["restitution"] = restitution_from(t_state, state["closing_mps"], start, end,
                                              settle)
    out["true_restitution"] = restitution_from(t_ideal, ideal["closing_mps"], start,
                                               ideal_force_end)
    n = min(len(state), len(ideal))
    if n:
        gap = state["flange"][:n] - ideal["position"][:n]
        out["path_error_m"] = float(np.max(np.linalg.norm(gap, axis=1)))
    return out
