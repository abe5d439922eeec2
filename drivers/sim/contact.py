"""The funnel contact's MuJoCo parameters from the scene's physical ones. Pure maths
and a write into the compiled model's ``geom_solref``; no I/O."""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import mujoco

from drivers.errors import ConfigError
from drivers.sim.scene import Scene

__all__ = ["ContactInfo", "configure_contact"]


@dataclass(frozen=True)
class ContactInfo:
    """Funnel contact parameters as MuJoCo sees them (for the record)."""

    m_eff: float
    solref_stiffness: float
    solref_damping: float


def configure_contact(scene: Scene, model: mujoco.MjModel, m_tcp: float, dt: float,
                      funnel_geoms: Iterable[int]) -> ContactInfo:
    """Map the scene's contact stiffness [N/m] and damping ratio onto solref.

    MuJoCo's direct solref is mass-normalised (fact sheet sec. 3): a
    contact with constant impedance d and reference stiffness k holds a
    quasi-static load F at penetration ``F (1 - d) / (d k m_eff)``. We pick
    k so that this equals ``F / stiffness``, with m_eff the reduced mass
    of the TCP (``m_tcp``: the Cartesian inertia along the approach axis) and
    the target. ``dt`` is the physics timestep.
    """
    ct = scene.contact
    m_eff = 1.0 / (1.0 / m_tcp + 1.0 / scene.target.mass)
    dimp = ct.impedance
    k = ct.stiffness * (1.0 - dimp) / (dimp * m_eff)
    limit = 1.0 / (2.0 * dt) ** 2
    if k > limit:
        raise ConfigError(
            scene.name, "contact.stiffness",
            f"{ct.stiffness:g} N/m maps to solref stiffness {k:.3g} > 1/(2h)^2 = {limit:.3g}; "
            "lower it or the physics timestep",
        )
    b = 2.0 * ct.damping_ratio * math.sqrt(dimp * k) / dimp
    for g in funnel_geoms:
        model.geom_solref[g, 0] = -k
        model.geom_solref[g, 1] = -b
    return ContactInfo(m_eff=m_eff, solref_stiffness=k, solref_damping=b)
