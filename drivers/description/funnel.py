"""The funnels' geometry that does not depend on how they are simulated. Pure maths.

The tool's funnel is a solid cone on a nose sphere, the target's a hollow cone
(:class:`~drivers.description.scene.FunnelGeometry`). With ``surface = "smooth"``
the tool's colliding surface is a stack of spheres on its axis, each inscribed in
the cone (the first is the nose); with ``"capsules"``, ``generators`` capsules
along the cone. The simulator builds its geoms from these numbers
(:mod:`drivers.world.funnels`); the seat depth and the tool's length are what the
layout, the judges and the 3-D view need.

Frames: the tool's tip (the TCP) is ``tool_tip_offset`` along the tool's axis
from the F/T sensor's tool-side face; a distance "behind the tip" is measured
back along that axis.
"""

from __future__ import annotations

import math

from drivers.description.scene import Scene

__all__ = ["capsule_tool_cone", "seat_depth", "tool_cone_spheres", "tool_tip_offset"]


def tool_tip_offset(scene: Scene) -> float:
    """Distance from the sensing face of the Mini45 to the TCP (tool tip) [m]."""
    return scene.tool.shaft_length + scene.tool.funnel.depth


def tool_cone_spheres(scene: Scene) -> list[tuple[float, float]]:
    """(distance of the centre behind the tip, radius) of every tool sphere [m].

    The tool cone has half-angle ``theta``, is tangent to the nose sphere
    (radius ``r_n``, centre ``r_n`` behind the tip) and ends ``depth`` behind
    the tip or where its radius reaches ``opening``, whichever comes first.
    A sphere whose centre lies ``a`` behind the tip is inscribed in the cone
    with radius ``(a - a_apex) sin(theta)``, where the cone's apex lies
    ``a_apex = r_n - r_n / sin(theta)`` behind the tip
    (ahead of it: negative). Between two inscribed spheres touching the
    generator ``ds`` apart, the surface dips by about ``ds^2 / (8 r)``; the
    spacing keeps that below ``scallop``.
    """
    f = scene.tool.funnel
    th = f.half_angle
    s, c = math.sin(th), math.cos(th)
    r_n = scene.tool.nose_radius
    a_apex = r_n - r_n / s
    # The last sphere's circle of tangency (radius rho cos(theta), at
    # a_apex + rho cos^2(theta) / sin(theta) behind the tip) is the cone's base.
    rho_last = min(f.opening / c, (f.depth - a_apex) * s / (c * c))
    out = [(r_n, r_n)]
    rho = r_n
    while rho < rho_last - 1e-9:
        ds = math.sqrt(8.0 * rho * f.scallop)  # spacing of tangency circles along the generator
        rho = min(rho + ds * math.tan(th), rho_last)
        out.append((a_apex + rho / s, rho))
    return out


def capsule_tool_cone(scene: Scene) -> tuple[float, float, float]:
    """Capsule tool: (axis radius at the nose end, at the base, surface offset c_m)."""
    f = scene.tool.funnel
    t = math.tan(f.half_angle)
    a2 = f.opening - f.capsule_radius
    a1 = max(0.0, a2 - (f.depth - scene.tool.nose_radius) * t)
    c_m = a1 + f.capsule_radius - scene.tool.nose_radius * t
    return a1, a2, c_m


def seat_depth(scene: Scene) -> float:
    """Insertion of the tool tip past the target's mouth when the funnels are seated [m].

    The coaxial tool slid into the target cone until it first touches it,
    capped at the funnel's depth. Smooth tool: a sphere of radius ``rho``
    centred ``a`` behind the tip touches the cone (half-angle ``theta``,
    mouth radius ``R``) when its centre is at depth
    ``(R - rho / cos(theta)) / tan(theta)``. Capsule tool: its cone surface
    ``c_m + s tan(theta)`` (equal half-angles assumed, as before).
    """
    tf = scene.target.funnel
    t = math.tan(tf.half_angle)
    if scene.tool.funnel.surface == "capsules":
        _, _, c_m = capsule_tool_cone(scene)
        return min((tf.opening - c_m) / math.tan(scene.tool.funnel.half_angle), tf.depth)
    c = math.cos(tf.half_angle)
    tips = [(tf.opening - rho / c) / t + a for a, rho in tool_cone_spheres(scene)]
    return min(min(tips), tf.depth)
