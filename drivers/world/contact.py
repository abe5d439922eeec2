"""The funnel contact: its MuJoCo parameters from the scene's physical ones
(:func:`configure_contact`, a write into the compiled model's ``geom_solref``) and
the wrench the target exerts on the tool (:class:`ToolContact`). No I/O."""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import mujoco
import numpy as np

from drivers.base.types import F64
from drivers.description.impact import DAMPING_RATIO_RANGE, damping_ratio_for, restitution_of
from drivers.description.scene import Scene
from drivers.errors import ConfigError

__all__ = ["DAMPING_RATIO_RANGE", "ContactInfo", "ToolContact", "configure_contact",
           "damping_ratio_for", "restitution_of"]


@dataclass(frozen=True)
class ContactInfo:
    """Funnel contact parameters as MuJoCo sees them (for the record)."""

    m_eff: float
    solref_stiffness: float
    solref_damping: float


def configure_contact(scene: Scene, model: mujoco.MjModel, m_tcp: float, dt: float,
                      funnel_geoms: Iterable[int]) -> ContactInfo:
    """Map the scene's contact stiffness [N/m] and restitution onto direct solref.

    MuJoCo's direct solref ``(-k, -b)`` is mass-normalised (fact sheet sec. 3).
    With solimp's impedance d (constant: ``contact.impedance``) MuJoCo 4 uses
    ``K = k / d^2`` and ``B = b / d`` in a contact's reference acceleration
    ``a_ref = -B v - K d r`` (``r``: the penetration, negative; ``efc_KBIP``),
    and one contact's normal acceleration is ``a = d a_ref + (1 - d) a_0``
    (``a_0``: without the contact). So one contact:

    * holds a quasi-static load F at ``r = -F (1 - d) / (k m_eff)``: k is
      ``contact.stiffness (1 - d) / m_eff``, with m_eff the reduced mass of the
      TCP (``m_tcp``: the Cartesian inertia along the approach axis) and the target;
    * in an impact (``a_0 = 0``) is a spring-damper of ``k`` and ``b`` per unit
      mass, whose damping ratio ``b / (2 sqrt k)`` gives the rebound
      (:func:`damping_ratio_for`).

    An impact that engages N contacts at once (the tool's sphere stack on
    several panels) has a collective mode whose impedance is
    ``d' = N d / (N d + 1 - d)`` (MuJoCo regularises each contact row alone,
    ``R = (1 - d) / d diagA``), anywhere in ``[d, 1)``: its stiffness and
    damping are ``d' / d`` times one contact's and its damping ratio
    ``sqrt(d' / d)`` times. ``b`` is set for the geometric middle of that
    range, ``d**(1/4)`` below the one-contact ratio, so that any impact's ratio
    is within ``d**(-1/4)`` of the one asked for (6 % at d = 0.8, 19 % at 0.5).

    Stability (``dt``: the physics timestep): the stiffest mode, ``k / d`` per
    unit mass, must stay below ``1 / (2 dt)^2`` and its damping ``b / d`` below
    ``1 / dt`` (explicit in every integrator but ``discrete``).
    """
    ct = scene.contact
    m_eff = 1.0 / (1.0 / m_tcp + 1.0 / scene.target.mass)
    dimp = ct.impedance
    k = ct.stiffness * (1.0 - dimp) / m_eff
    limit = 1.0 / (2.0 * dt) ** 2
    if k / dimp > limit:
        raise ConfigError(
            scene.name, "contact.stiffness",
            f"{ct.stiffness:g} N/m maps to solref stiffness {k:.3g} (/ impedance "
            f"{k / dimp:.3g}) > 1/(2h)^2 = {limit:.3g}; lower it or the physics timestep",
        )
    b = 2.0 * damping_ratio_for(ct.restitution) * math.sqrt(k) * dimp ** 0.25
    if b / dimp * dt > 1.0:
        raise ConfigError(
            scene.name, "contact.restitution",
            f"{ct.restitution:g} maps to solref damping {b:.3g} (/ impedance {b / dimp:.3g}) "
            f"> 1/h = {1.0 / dt:.3g}; raise it or lower the physics timestep",
        )
    for g in funnel_geoms:
        model.geom_solref[g, 0] = -k
        model.geom_solref[g, 1] = -b
    return ContactInfo(m_eff=m_eff, solref_stiffness=k, solref_damping=b)


def _apart_bounds(model: mujoco.MjModel, data: mujoco.MjData, tool_body: int,
                  tool_geoms: set[int]) -> list[tuple[F64, float]] | None:
    """For each body with a geom the tool's geoms can collide with (contype and
    conaffinity): a view of its position and the squared distance from the tool
    body's origin within which a contact may exist: the two bodies' bounding
    spheres (geom offset + ``rbound``) plus twice the largest margin and gap, and
    1 mm. Beyond it MuJoCo's collision makes no contact between them. ``None``
    (no shortcut) for explicit contact pairs or an unbounded geom (a plane)."""
    ct, ca = model.geom_contype, model.geom_conaffinity
    tool = sorted(tool_geoms)
    others = [g for g in range(model.ngeom) if g not in tool_geoms
              and any((ct[t] & ca[g]) or (ct[g] & ca[t]) for t in tool)]
    if model.npair or not tool or any(model.geom_rbound[g] <= 0.0 for g in tool + others):
        return None

    def radius(geoms: list[int]) -> float:
        return max(float(np.linalg.norm(model.geom_pos[g])) + float(model.geom_rbound[g])
                   for g in geoms)

    slack = 2.0 * float(max(model.geom_margin[g] + model.geom_gap[g] for g in tool + others))
    r_tool = radius(tool)
    out = []
    for body in sorted({int(model.geom_bodyid[g]) for g in others}):
        if body == tool_body:
            return None
        reach = r_tool + radius([g for g in others if model.geom_bodyid[g] == body]) + slack + 1e-3
        out.append((data.xpos[body], reach * reach))
    return out


class ToolContact:
    """The true wrench the target exerts on the tool (TCF at the TCP), from ``data``.

    Args:
        model, data: the world's.
        tool_body: the tool's body id.
        tool_geoms: the tool's colliding geoms.
        tcp: the TCP site id.
    """

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, tool_body: int,
                 tool_geoms: set[int], tcp: int) -> None:
        self._m, self._d = model, data
        self._is_tool_geom = np.zeros(model.ngeom, dtype=bool)
        self._is_tool_geom[list(tool_geoms)] = True
        # views into MuJoCo's buffers
        self._cfrc_tool = data.cfrc_ext[tool_body]
        self._tool_com = data.subtree_com[int(model.body_rootid[tool_body])]
        self._tcp_xpos = data.site_xpos[tcp]
        self._tcp_rot = data.site_xmat[tcp].reshape(3, 3)
        self._tool_xpos = data.xpos[tool_body]
        self._apart = _apart_bounds(model, data, tool_body, tool_geoms)
        from drivers.world import kernels  # numba: imported when a world is built

        self._touches = kernels.touches
        self._wrench_at_tcp = kernels.tool_wrench
        self.kernel_args = (self._is_tool_geom, self._cfrc_tool, self._tool_com, self._tcp_xpos,
                            self._tcp_rot)
        """What :func:`drivers.world.kernels.post_step` takes for this contact (views)."""

    def wrench(self) -> tuple[F64, bool]:
        """The wrench and whether touching, at the current state.

        Valid only right after ``mj_step``/``mj_forward`` (contacts and
        constraint forces must come from the same collision pass). Touching:
        a tool geom is in the contact list (within the margin counts). The
        wrench is the tool body's external force from MuJoCo's
        ``mj_rnePostConstraint`` (the sum of its contacts' forces, which only
        the target funnel makes: the contype convention), moved from the
        subtree centre of mass to the TCP.
        """
        d = self._d
        ncon = d.ncon
        if ncon == 0:
            return np.zeros(6), False
        if self._apart is not None:  # far from all it can touch: no contact (plain floats)
            tx, ty, tz = self._tool_xpos.tolist()
            for xpos, reach2 in self._apart:
                x, y, z = xpos.tolist()
                if (tx - x) ** 2 + (ty - y) ** 2 + (tz - z) ** 2 <= reach2:
                    break
            else:
                return np.zeros(6), False
        if not self._touches(d.contact.geom, self._is_tool_geom):
            return np.zeros(6), False
        mujoco.mj_rnePostConstraint(self._m, d)
        # [torque about the subtree com, force], world -> at the TCP, TCF (kernels.py)
        out = np.empty(6)
        self._wrench_at_tcp(self._cfrc_tool, self._tool_com, self._tcp_xpos, self._tcp_rot, out)
        return out, True
