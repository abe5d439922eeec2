"""The recording's message classes and the JSON-schema fragments of Foxglove's types.

The fixed-layout CDR message classes (:class:`FieldSpec`, :class:`MessageSpec`,
:class:`CdrTopic`, :class:`JsonTopic`) are robot-neutral and live in
:mod:`drivers.base.topics`, so that a back-end can describe the topics of its
extras without importing ``ffexp``; they are imported here for the recording.
"""

from __future__ import annotations

from drivers.base.topics import (
    _PRIMITIVES,
    _STRUCT_CODES,
    CDR_HEADER,
    CdrTopic,
    FieldSpec,
    JsonTopic,
    MessageSpec,
)

__all__ = [
    "CDR_HEADER",
    "QUAT_SCHEMA",
    "TIME_SCHEMA",
    "VEC3_SCHEMA",
    "_PRIMITIVES",
    "_STRUCT_CODES",
    "CdrTopic",
    "FieldSpec",
    "JsonTopic",
    "MessageSpec",
]

#: JSON-schema fragments of Foxglove's well-known types (time, vector, quaternion).
TIME_SCHEMA = {
    "type": "object",
    "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}},
}
VEC3_SCHEMA = {
    "type": "object",
    "properties": {k: {"type": "number"} for k in ("x", "y", "z")},
}
QUAT_SCHEMA = {
    "type": "object",
    "properties": {k: {"type": "number"} for k in ("x", "y", "z", "w")},
}
