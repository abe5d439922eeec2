"""The rig as ``foxglove.SceneUpdate`` entities: simple shapes from the scene file. Pure.

Every entity is locked to a ``/tf`` frame and placed in it:

- ``bed`` (frame ``base``): the air bed's glass, a thin slab whose top is the
  glass plane, centred under the target's start position
  (:func:`drivers.description.layout.compute_layout`); the scene gives no bed size, so
  it is :data:`BED_SIZE_M` square;
- ``base``, ``link1`` .. ``link{n}`` (the scene's arm, ``arm.description``:
  seven links for the LWR4+, six for the UR5e): the links as cylinders of the
  simulator's link capsules (0.06 m radius, from the link's origin to the
  next joint's, the last one's to the flange or 20 mm along z);
- ``tool`` (frame ``link{n}``, placed at the flange): the F/T sensor, the
  adapter shaft and the tool funnel, a cone on the nose whose tip is the TCF;
- ``target`` (the target's frame): the block and its funnel, a hollow cone
  drawn as a translucent frustum whose wide end is the funnel mouth, its axis
  along the block's +x (:mod:`drivers.description.funnel`);
- ``target_tracked``: in simulation with a tracker, the same in green and
  translucent in the tracker's frame (what the camera model sees).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from drivers.base.types import F64, NS_PER_S
from drivers.description import ArmDescription, Layout, Scene, tool_tip_offset
from ffexp.recording.recorder import pose_to_transform
from ffexp.recording.topics.scene import PRIMITIVES
from ffexp.scene3d.kinematics import flange_in_last_link, link_frames

__all__ = ["BED_SIZE_M", "LINK_RADIUS_M", "scene_update"]

#: Side of the drawn air bed [m] (the scene has no bed size; the simulator's plane is unbounded).
BED_SIZE_M = 1.0
_BED_THICKNESS_M = 0.02
#: Radius of the links' cylinders [m] (the simulator's link capsules).
LINK_RADIUS_M = 0.06
#: Height of the base's cylinder [m] (the simulator's drawn base).
_BASE_HEIGHT_M = 0.11
#: The last link's cylinder of an arm without fixed turns [m] (the simulator's flange capsule).
_FLANGE_CAPSULE_M = (0.0, 0.0, 0.02)
_SHAFT_RADIUS_M = 0.012

_ORANGE = {"r": 1.0, "g": 0.5, "b": 0.0, "a": 0.8}
_GREY = {"r": 0.6, "g": 0.6, "b": 0.6, "a": 1.0}
_DARK = {"r": 0.2, "g": 0.2, "b": 0.2, "a": 1.0}
_BLUE = {"r": 0.3, "g": 0.5, "b": 0.9, "a": 1.0}
_BLUE_GLASS = {"r": 0.3, "g": 0.5, "b": 0.9, "a": 0.45}
_ALU = {"r": 0.75, "g": 0.75, "b": 0.8, "a": 1.0}
_GLASS = {"r": 0.8, "g": 0.9, "b": 1.0, "a": 0.3}
_GHOST = {"r": 0.2, "g": 0.9, "b": 0.3, "a": 0.3}
_GOLD = {"r": 0.85, "g": 0.75, "b": 0.3, "a": 1.0}
_GREEN = {"r": 0.4, "g": 0.7, "b": 0.4, "a": 1.0}

#: Rotation taking a primitive's z axis to +x (a funnel's axis in the target).
_Z_TO_X = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])


def _pose(position: F64 | tuple[float, ...], rotation: F64 | None = None) -> dict[str, Any]:
    m = np.eye(4)
    if rotation is not None:
        m[:3, :3] = rotation
    m[:3, 3] = position
    t, q = pose_to_transform(m)
    return {"position": t, "orientation": q}


def _vec(x: float, y: float, z: float) -> dict[str, float]:
    return {"x": float(x), "y": float(y), "z": float(z)}


def _cylinder(z0: float, z1: float, radius0: float, radius1: float,
              color: dict[str, float], rotation: F64 | None = None,
              origin: F64 | None = None) -> dict[str, Any]:
    """A frustum along the z axis (of ``rotation``, from ``origin``) from ``z0``
    (radius ``radius0``) to ``z1`` (radius ``radius1``)."""
    r = max(radius0, radius1)
    axis = np.array([0.0, 0.0, 1.0]) if rotation is None else rotation[:, 2]
    centre = (np.zeros(3) if origin is None else origin) + axis * (z0 + z1) / 2.0
    return {"pose": _pose(centre, rotation), "size": _vec(2 * r, 2 * r, abs(z1 - z0)),
            "bottom_scale": radius0 / r, "top_scale": radius1 / r, "color": color}


def _along(v: tuple[float, float, float]) -> F64 | None:
    """A rotation taking z to the direction of ``v`` (``None``: ``v`` is along +z)."""
    if v[0] == 0.0 and v[1] == 0.0 and v[2] > 0.0:
        return None
    z = np.asarray(v, dtype=np.float64) / math.hypot(*v)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.column_stack((x, np.cross(z, x), z))


def _links(arm: ArmDescription) -> list[tuple[str, list[dict[str, Any]]]]:
    """Each link's frame and cylinder: from its origin to the next joint's (the last
    link's to the flange of a DH arm, else :data:`_FLANGE_CAPSULE_M`), as the simulator."""
    last = arm.flange_m if arm.joint_rpy_rad is not None else _FLANGE_CAPSULE_M
    ends = (*arm.joint_origins_m[1:], last)
    out: list[tuple[str, list[dict[str, Any]]]] = []
    for frame, end in zip(link_frames(arm), ends, strict=True):
        if not any(end):  # the next joint at this one's origin: nothing to draw
            out.append((frame, []))
            continue
        turn = _along(end)
        length = end[2] if turn is None else math.hypot(*end)
        out.append((frame, [_cylinder(0.0, length, LINK_RADIUS_M, LINK_RADIUS_M, _ORANGE,
                                      rotation=turn)]))
    return out


def _entity(stamp: dict[str, int], frame: str, name: str,
            **primitives: list[Any]) -> dict[str, Any]:
    return {"timestamp": stamp, "frame_id": frame, "id": name,
            "lifetime": {"sec": 0, "nsec": 0}, "frame_locked": True,
            "metadata": [{"key": "source", "value": "ffexp.scene3d"}],
            **{p: primitives.get(p, []) for p in PRIMITIVES}}


def tool_funnel_radius(scene: Scene) -> float:
    """Radius of the tool cone's base [m]: where it reaches ``opening`` or ``depth``."""
    f = scene.tool.funnel
    return min(f.opening, scene.tool.nose_radius + f.depth * math.tan(f.half_angle))


def target_funnel_inner_radius(scene: Scene) -> float:
    """Radius of the target funnel at its depth [m] (its narrow end)."""
    f = scene.target.funnel
    return max(f.opening - f.depth * math.tan(f.half_angle), 0.0)


def _objects(scene: Scene, layout: Layout, stamp: dict[str, int]) -> list[dict[str, Any]]:
    """The scene's ``[[objects]]``: a free one on its own /tf frame (the truth's, by its
    name), a fixed one where the layout put it."""
    out = []
    for obj in scene.objects:
        a, b, c = obj.size
        free = obj.support == "free"
        at = (0.0, 0.0, 0.0) if free else tuple(layout.objects[obj.name])
        frame = obj.name if free else "base"
        if obj.shape == "box":
            prims = {"cubes": [{"pose": _pose(at), "size": _vec(a, b, c), "color": _GREEN}]}
        elif obj.shape == "sphere":
            prims = {"spheres": [{"pose": _pose(at), "size": _vec(a, a, a), "color": _GREEN}]}
        else:
            prims = {"cylinders": [_cylinder(-c / 2, c / 2, a / 2, a / 2, _GREEN,
                                             origin=np.asarray(at))]}
        out.append(_entity(stamp, frame, obj.name, **prims))
    return out


def scene_update(scene: Scene, layout: Layout, time_ns: int, target_frame: str,
                 base: F64, tracked_frame: str = "") -> dict[str, Any]:
    """The whole rig as one SceneUpdate message at log time ``time_ns``.

    ``layout`` places bed and target as the simulator does (in the robot's
    frame), ``target_frame`` is the ``/tf`` frame of the target block,
    ``base`` the arm's base in the robot's frame; ``tracked_frame``, when
    given, the frame of the tracker's target, drawn as a translucent ghost
    (``target_tracked``) beside the true one."""
    sec, nsec = divmod(time_ns, NS_PER_S)
    stamp = {"sec": sec, "nsec": nsec}
    entities = []
    if scene.target.support == "air_bed":
        top = layout.glass_z
        bed = {"pose": _pose((layout.target_pos[0], layout.target_pos[1],
                              top - _BED_THICKNESS_M / 2.0)),
               "size": _vec(BED_SIZE_M, BED_SIZE_M, _BED_THICKNESS_M), "color": _GLASS}
        entities.append(_entity(stamp, "base", "bed", cubes=[bed]))
    if scene.base.floating:  # the chaser's body, on its own /tf frame (the truth's)
        entities.append(_entity(stamp, "chaser", "chaser", cubes=[{
            "pose": _pose((0.0, 0.0, 0.0)), "size": _vec(*scene.base.size), "color": _GOLD}]))
    entities += _objects(scene, layout, stamp)
    base_pos = base[:3, 3]
    entities.append(_entity(stamp, "base", "base", cylinders=[
        _cylinder(0.0, _BASE_HEIGHT_M, LINK_RADIUS_M, LINK_RADIUS_M, _GREY, origin=base_pos)]))
    arm = scene.arm.description
    for frame, cylinders in _links(arm):
        entities.append(_entity(stamp, frame, frame, cylinders=cylinders))
    flange = flange_in_last_link(arm)
    at_flange: dict[str, F64] = {} if flange is None else {
        "rotation": flange[:3, :3], "origin": flange[:3, 3]}
    tool = scene.tool
    h_s = tool.sensor_height
    cone_base = h_s + tool.shaft_length
    tip = h_s + tool_tip_offset(scene)
    r_cone = tool_funnel_radius(scene)
    entities.append(_entity(stamp, link_frames(arm)[-1], "tool", cylinders=[
        _cylinder(0.0, h_s, tool.sensor_radius, tool.sensor_radius, _DARK, **at_flange),
        _cylinder(h_s, cone_base, _SHAFT_RADIUS_M, _SHAFT_RADIUS_M, _GREY, **at_flange),
        _cylinder(cone_base, tip, r_cone, min(tool.nose_radius, r_cone), _BLUE, **at_flange),
    ]))
    tg = scene.target
    mouth = np.asarray(layout.funnel_in_target, dtype=np.float64)
    block = {"pose": _pose((0.0, 0.0, 0.0)), "size": _vec(*tg.size), "color": _ALU}
    funnel = _cylinder(0.0, tg.funnel.depth, tg.funnel.opening,
                       target_funnel_inner_radius(scene), _BLUE_GLASS,
                       rotation=_Z_TO_X, origin=mouth)
    entities.append(_entity(stamp, target_frame, "target", cubes=[block], cylinders=[funnel]))
    if tracked_frame:
        ghost = {**block, "color": _GHOST}
        entities.append(_entity(stamp, tracked_frame, "target_tracked", cubes=[ghost],
                                cylinders=[{**funnel, "color": _GHOST}]))
    return {"deletions": [], "entities": entities}
