"""Fixed-layout ROS 2 messages (``ros2msg`` schema, ``cdr`` encoding) as numpy dtypes.

Every high-rate topic of a run is a flat ROS 2 message made only of
fixed-size primitives and fixed-size arrays (``float64[7] msr_jnt_pos``). In
CDR such a message is a 4-byte encapsulation header followed by the fields,
each aligned to its own size (at most 8) counted from the end of the header,
with no length prefixes. Its bytes are therefore exactly a numpy structured
record with explicit offsets: encoding is ``record.tobytes()`` and decoding a
whole topic is one ``np.frombuffer`` over the concatenated messages. Foxglove
and ``mcap_ros2`` decode the same bytes from the schema text.

Robot-neutral: a back-end describes the recording topics of its extras
(:class:`~drivers.base.types.Extras`) with these classes, and the recording's
registry (:mod:`ffexp.recording.topics`) collects them from
:mod:`drivers.registry`.
"""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

__all__ = ["CDR_HEADER", "CdrTopic", "FieldSpec", "JsonTopic", "MessageSpec"]

#: CDR encapsulation header: plain CDR, little endian.
CDR_HEADER = b"\x00\x01\x00\x00"

_PRIMITIVES: dict[str, str] = {
    "float64": "<f8",
    "float32": "<f4",
    "int64": "<i8",
    "uint64": "<u8",
    "int32": "<i4",
    "uint32": "<u4",
    "int16": "<i2",
    "uint16": "<u2",
    "int8": "i1",
    "uint8": "u1",
    "bool": "u1",
}

#: ``struct`` codes of the same primitives (little endian, no implicit padding).
_STRUCT_CODES: dict[str, str] = {
    "float64": "d", "float32": "f", "int64": "q", "uint64": "Q", "int32": "i",
    "uint32": "I", "int16": "h", "uint16": "H", "int8": "b", "uint8": "B", "bool": "B",
}


@dataclass(frozen=True)
class FieldSpec:
    """One field: ROS 2 primitive type, element count (1 = scalar), unit, meaning."""

    name: str
    type: str
    count: int = 1
    unit: str = ""
    doc: str = ""

    def __post_init__(self) -> None:
        if self.type not in _PRIMITIVES:
            raise ValueError(f"{self.name}: unsupported type {self.type}")
        if self.count < 1:
            raise ValueError(f"{self.name}: count must be >= 1")


@dataclass(frozen=True)
class MessageSpec:
    """A flat message type and the numpy dtype of its CDR bytes."""

    name: str
    """Fully qualified ROS 2 type, e.g. ``ffexp_msgs/msg/Wrench``."""
    fields: tuple[FieldSpec, ...]
    doc: str = ""

    @property
    def ros2msg(self) -> str:
        """The schema text: one ``type[count] name`` line per field."""
        lines = []
        for f in self.fields:
            array = f"[{f.count}]" if f.count > 1 else ""
            comment = " ".join(x for x in (f"[{f.unit}]" if f.unit else "", f.doc) if x)
            lines.append(f"{f.type}{array} {f.name}" + (f"  # {comment}" if comment else ""))
        return "\n".join(lines) + "\n"

    @property
    def dtype(self) -> np.dtype[np.void]:
        """Structured dtype of header + fields with CDR alignment."""
        names, formats, offsets = ["_cdr_header"], ["V4"], [0]
        pos = 0  # relative to the end of the header
        for f in self.fields:
            base = np.dtype(_PRIMITIVES[f.type])
            align = min(base.itemsize, 8)
            pos = (pos + align - 1) // align * align
            names.append(f.name)
            formats.append(base.str if f.count == 1 else f"({f.count},){base.str}")
            offsets.append(4 + pos)
            pos += base.itemsize * f.count
        return np.dtype(
            {"names": names, "formats": formats, "offsets": offsets, "itemsize": 4 + pos}
        )

    @cached_property
    def layout(self) -> struct.Struct:
        """The same layout as :attr:`dtype` as a ``struct.Struct``: ``pack(CDR_HEADER,
        *values)`` with the fields' values flattened in order (an array field's
        elements one by one) gives the bytes of the record holding those values."""
        fmt, pos = ["<4s"], 0
        for f in self.fields:
            size = np.dtype(_PRIMITIVES[f.type]).itemsize
            align = min(size, 8)
            pad = (pos + align - 1) // align * align - pos
            if pad:
                fmt.append(f"{pad}x")
            fmt.append(f"{f.count}{_STRUCT_CODES[f.type]}")
            pos += pad + size * f.count
        return struct.Struct("".join(fmt))

    def new_record(self) -> np.ndarray:
        """A zeroed one-element record array with the CDR header set."""
        rec = np.zeros(1, dtype=self.dtype)
        rec["_cdr_header"] = np.frombuffer(CDR_HEADER, dtype="V4")[0]
        return rec


@dataclass(frozen=True)
class CdrTopic:
    """A topic whose messages are one fixed-layout CDR message type."""

    topic: str
    spec: MessageSpec
    rate: str


@dataclass(frozen=True)
class JsonTopic:
    """A low-rate topic of JSON messages with a JSON schema."""

    topic: str
    schema_name: str
    schema: dict[str, Any]
    rate: str
    doc: str

    @property
    def schema_bytes(self) -> bytes:
        return json.dumps(self.schema).encode()
