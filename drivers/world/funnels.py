"""Funnel contact geometry: smooth cones from MuJoCo primitives.

MuJoCo collides convex shapes only, and the target's funnel is a hollow cone.
Two surfaces are built so that the contact normal varies smoothly with where
the tool lands:

* **Target (hollow cone): flat panels.** ``panels`` thin boxes whose inner
  faces are the planes tangent to the cone along ``panels`` generators (a
  polygonal cone circumscribing the true one). Neighbouring faces meet at
  creases that turn by only ``360 / panels`` degrees, and a sphere never sits
  in a groove (the old 16-capsule funnel had 10 mm gaps between 6 mm ridges).
* **Tool (solid cone on a nose): spheres on its axis.** A sphere centred on the
  axis of a cone and inscribed in it touches the cone along a whole circle, so
  a stack of such spheres is the cone up to shallow axial scallops whose depth
  is bounded by ``scallop`` (chosen per sphere from its radius); around the
  axis it is exactly round. The first sphere is the nose.

Sphere-box is one of MuJoCo's primitive collision pairs (one contact per pair,
no iterative CCD). The old capsule generators remain selectable
(``surface = "capsules"``) to compare against. The spheres' sizes and the seat
depth are the funnels' geometry (:mod:`drivers.description.funnel`); this module
writes them as MJCF.

Frames: the target funnel's mouth centre is the origin of body
``target_funnel``, its axis +x (into the target); the tool's tip is at
``z = tip_z`` of body ``tool``, its axis +z (toward the tip).
"""

from __future__ import annotations

import math

import numpy as np

from drivers.description.funnel import capsule_tool_cone, tool_cone_spheres
from drivers.description.scene import FunnelGeometry, Scene

__all__ = ["mjcf_num", "mjcf_vec", "target_funnel_geoms", "tool_funnel_geoms"]

_TOOL = 'contype="1" conaffinity="2"'
_TARGET = 'contype="2" conaffinity="1"'


def mjcf_num(v: float) -> str:
    """A number as the scene's MJCF writes it (9 significant digits)."""
    return f"{v:.9g}"


def mjcf_vec(v: object) -> str:
    """Numbers as the scene's MJCF writes them, separated by spaces."""
    return " ".join(mjcf_num(float(x)) for x in v)  # type: ignore[attr-defined]


# ----------------------------------------------------------------- the tool
def tool_funnel_geoms(scene: Scene, tip_z: float, funnel_class: str) -> str:
    """The tool's colliding geoms (and none of its visual ones)."""
    f = scene.tool.funnel
    if f.surface == "capsules":
        return _tool_capsules(scene, tip_z, funnel_class)
    out = []
    for k, (a, rho) in enumerate(tool_cone_spheres(scene)):
        name = "tool_nose" if k == 0 else f"tool_sphere{k}"
        out.append(
            f'<geom name="{name}" type="sphere" size="{mjcf_num(rho)}" '
            f'pos="0 0 {mjcf_num(tip_z - a)}" '
            f'{_TOOL} class="{funnel_class}"/>'
        )
    return "\n".join(out)


def _tool_capsules(scene: Scene, tip_z: float, funnel_class: str) -> str:
    f = scene.tool.funnel
    a1, a2, _ = capsule_tool_cone(scene)
    nose = scene.tool.nose_radius
    z1 = tip_z - nose
    z2 = tip_z - f.depth
    out = [
        f'<geom name="tool_nose" type="sphere" size="{mjcf_num(nose)}" pos="0 0 {mjcf_num(z1)}" '
        f'{_TOOL} class="{funnel_class}"/>'
    ]
    for k in range(f.generators):
        phi = (k + 0.5) * 2.0 * math.pi / f.generators
        c, s = math.cos(phi), math.sin(phi)
        out.append(
            f'<geom name="tool_gen{k}" type="capsule" size="{mjcf_num(f.capsule_radius)}" '
            f'fromto="{mjcf_vec((a1 * c, a1 * s, z1, a2 * c, a2 * s, z2))}" '
            f'{_TOOL} class="{funnel_class}"/>'
        )
    return "\n".join(out)


# --------------------------------------------------------------- the target
def target_funnel_geoms(f: FunnelGeometry, funnel_class: str) -> str:
    """The hollow cone along +x from the mouth at the origin."""
    if f.surface == "capsules":
        return _target_capsules(f, funnel_class)
    th = f.half_angle
    s, c = math.sin(th), math.cos(th)
    n = f.panels
    half_len = f.depth / c / 2.0
    half_width = f.opening * math.tan(math.pi / n)  # the polygon's side at the mouth
    half_thick = f.wall / 2.0
    r_mid = f.opening - f.depth / 2.0 * math.tan(th)
    out = []
    for k in range(n):
        phi = k * 2.0 * math.pi / n
        e_r = np.array([0.0, math.cos(phi), math.sin(phi)])
        e_phi = np.array([0.0, -math.sin(phi), math.cos(phi)])
        along = np.array([c, 0.0, 0.0]) - s * e_r  # down the generator, toward the apex
        outward = np.array([s, 0.0, 0.0]) + c * e_r  # into the wall
        centre = np.array([f.depth / 2.0, 0.0, 0.0]) + r_mid * e_r + half_thick * outward
        out.append(
            f'<geom name="target_panel{k}" type="box" '
            f'size="{mjcf_vec((half_len, half_width, half_thick))}" pos="{mjcf_vec(centre)}" '
            f'xyaxes="{mjcf_vec(along)} {mjcf_vec(e_phi)}" {_TARGET} class="{funnel_class}"/>'
        )
    return "\n".join(out)


def _target_capsules(f: FunnelGeometry, funnel_class: str) -> str:
    t = math.tan(f.half_angle)
    r = f.capsule_radius
    r1 = f.opening + r
    r2 = max(f.opening - f.depth * t, 0.0) + r
    out = []
    for k in range(f.generators):
        phi = k * 2.0 * math.pi / f.generators
        c, s = math.cos(phi), math.sin(phi)
        out.append(
            f'<geom name="target_gen{k}" type="capsule" size="{mjcf_num(r)}" '
            f'fromto="0 {mjcf_vec((r1 * c, r1 * s, f.depth, r2 * c, r2 * s))}" '
            f'{_TARGET} class="{funnel_class}"/>'
        )
    return "\n".join(out)

