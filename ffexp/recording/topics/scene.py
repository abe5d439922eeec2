"""Topics of the 3-D scene of the rig: a group of :mod:`ffexp.recording.topics`.

Message specs and topics are defined here with the classes of
:mod:`ffexp.recording.schema`; ``topics.py`` puts them in the one registry
(``CDR_TOPICS``, ``JSON_TOPICS``), so every recorder, reader and ``ffexp topics``
sees them.

``/scene/rig`` is a ``foxglove.SceneUpdate`` (JSON) of the rig's bodies as
simple shapes (:mod:`ffexp.scene3d`): the air bed, the arm's links, the
sensor and the tool funnel, the target block with its funnel. Each entity is
locked to a frame of ``/tf`` (``base``, ``link1`` .. ``link7``, ``target``,
``target_tracked`` or ``target_nominal``), so the shapes move with the
transforms; the update itself is written at the start and then about once a
second (a viewer that connects later gets it too).
"""

from __future__ import annotations

from typing import Any

from ffexp.recording.schema import QUAT_SCHEMA, TIME_SCHEMA, VEC3_SCHEMA, CdrTopic, JsonTopic

_POSE = {"type": "object", "properties": {"position": VEC3_SCHEMA,
                                          "orientation": QUAT_SCHEMA}}
_COLOR = {"type": "object",
          "properties": {k: {"type": "number"} for k in ("r", "g", "b", "a")}}
_CUBE = {"type": "object", "properties": {"pose": _POSE, "size": VEC3_SCHEMA, "color": _COLOR}}
_CYLINDER = {
    "type": "object",
    "properties": {
        "pose": _POSE, "size": VEC3_SCHEMA, "color": _COLOR,
        "bottom_scale": {"type": "number", "description": "radius scale at -z (1: size)"},
        "top_scale": {"type": "number", "description": "radius scale at +z (0: a cone)"},
    },
}
_TEXT = {
    "type": "object",
    "properties": {"pose": _POSE, "billboard": {"type": "boolean"},
                   "font_size": {"type": "number"}, "scale_invariant": {"type": "boolean"},
                   "color": _COLOR, "text": {"type": "string"}},
}
_ANY_LIST: dict[str, Any] = {"type": "array", "items": {"type": "object"}}

#: Primitive lists of ``foxglove.SceneEntity``; those not used here are written empty.
PRIMITIVES = ("arrows", "cubes", "spheres", "cylinders", "lines", "triangles", "texts", "models")

SCENE_UPDATE_SCHEMA: dict[str, Any] = {
    "title": "foxglove.SceneUpdate",
    "type": "object",
    "properties": {
        "deletions": {
            "type": "array",
            "items": {"type": "object", "properties": {
                "timestamp": TIME_SCHEMA,
                "type": {"type": "integer", "description": "0 matching id, 1 all"},
                "id": {"type": "string"}}},
        },
        "entities": {
            "type": "array",
            "items": {
                "type": "object",
                "properties": {
                    "timestamp": TIME_SCHEMA,
                    "frame_id": {"type": "string", "description": "a frame of /tf"},
                    "id": {"type": "string"},
                    "lifetime": TIME_SCHEMA,
                    "frame_locked": {"type": "boolean"},
                    "metadata": {"type": "array", "items": {"type": "object", "properties": {
                        "key": {"type": "string"}, "value": {"type": "string"}}}},
                    **{name: _ANY_LIST for name in PRIMITIVES},
                    "cubes": {"type": "array", "items": _CUBE},
                    "cylinders": {"type": "array", "items": _CYLINDER},
                    "texts": {"type": "array", "items": _TEXT},
                },
                "required": ["frame_id", "id", "frame_locked", *PRIMITIVES],
            },
        },
    },
    "required": ["deletions", "entities"],
}

CDR: tuple[CdrTopic, ...] = ()
JSON: tuple[JsonTopic, ...] = (
    JsonTopic("/scene/rig", "foxglove.SceneUpdate", SCENE_UPDATE_SCHEMA,
              "at the start, then about once a second",
              "The rig as simple shapes (bed, arm links, tool funnel, target block and "
              "funnel), each locked to a /tf frame."),
)
