"""What a run imparted to the scene's free bodies, from its recording. Pure maths on arrays.

In free flight every newton-second the tool pushes is the target's motion: the
target's momentum change over the run (from the simulator's truth) and the
contact impulse the F/T sensor measured (its wrench turned into the world
frame and integrated) are the same number, up to what else acts on the target
(bed friction and hose on the air bed, none in orbit). For a floating base the
largest displacement and rotation of the base from where it started.
"""

from __future__ import annotations

import math

import numpy as np

from drivers.base.types import F64

__all__ = ["base_excursion", "contact_impulse_ns", "momentum_change_ns"]


def momentum_change_ns(mass_kg: float, twist: F64) -> float:
    """``|m (v_end - v_start)|`` of a body from its twists ``[v, w]`` (rows, world) [N s]."""
    if len(twist) == 0:
        return 0.0
    return float(mass_kg * np.linalg.norm(twist[-1, :3] - twist[0, :3]))


def contact_impulse_ns(t_s: F64, wrench_tcf: F64, tcf_rot: F64, in_contact: F64) -> float:
    """``|sum R f dt|`` from the first cycle in contact to the last: the impulse of the
    measured contact force (TCF, the environment on the tool) in the world frame [N s].
    Each cycle counts its force for the time to the next. Light touches between the
    detector's contacts count (a detector misses many in free flight); before the first
    contact and after the last the reading is the sensor's noise and drift, which
    would otherwise add up over a long run.

    ``tcf_rot`` is ``(n, 3, 3)``: the TCF's axes in the world frame."""
    if len(t_s) < 2:
        return 0.0
    touching = np.flatnonzero(np.asarray(in_contact, bool))
    if len(touching) == 0:
        return 0.0
    window = slice(int(touching[0]), int(touching[-1]) + 1)
    f_world = np.einsum("nij,nj->ni", tcf_rot[window], wrench_tcf[window, :3])
    dt = np.diff(t_s, append=t_s[-1])[window, None]
    return float(np.linalg.norm(np.sum(f_world * dt, axis=0)))


def base_excursion(pose: F64) -> tuple[float, float]:
    """The largest distance [m] and rotation [deg] of a body from its first pose
    (``(n, 4, 4)``; the rotation is the angle of ``R_0^T R``)."""
    if len(pose) == 0:
        return 0.0, 0.0
    d = np.linalg.norm(pose[:, :3, 3] - pose[0, :3, 3], axis=1)
    rel = np.einsum("ji,njk->nik", pose[0, :3, :3], pose[:, :3, :3])
    cos = np.clip((np.trace(rel, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    return float(np.max(d)), math.degrees(float(np.max(np.arccos(cos))))
