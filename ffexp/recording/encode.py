"""Encoding a CDR message from an object's same-named attributes, without numpy records.

:class:`FieldsEncoder` compiles a :class:`~ffexp.recording.schema.MessageSpec`
into segments: each array field whose value is a numpy array of the field's
type and size is copied as its bytes (``tobytes``, row-major: a 4x4 pose as its
16 numbers), and each run of scalar fields is packed with one ``struct``
layout that includes the CDR padding. The bytes are those of the spec's numpy
record filled with the same values (``tests/test_recording_encode.py``); a value
that numpy would convert (a float into an integer field, a list, an array of
another type or size) makes :meth:`FieldsEncoder.encode` return ``None``, and
the caller fills the numpy record instead.
"""

from __future__ import annotations

import struct
from typing import Any

import numpy as np

from ffexp.recording.schema import _PRIMITIVES, _STRUCT_CODES, CDR_HEADER, MessageSpec

#: Segment kinds.
_ARRAY, _SCALARS = 0, 1


class FieldsEncoder:
    """The bytes of one message of ``spec`` from the attributes of an object."""

    def __init__(self, spec: MessageSpec) -> None:
        self.spec = spec
        segments: list[tuple[int, Any, Any, Any, bytes]] = []
        fmt: list[str] = []
        names: list[str] = []
        pad_before = b""
        pos = 0  # relative to the end of the CDR header

        def close_scalars() -> None:
            nonlocal fmt, names
            if names:
                segments.append((_SCALARS, struct.Struct("<" + "".join(fmt)), tuple(names),
                                 None, b""))
            fmt, names = [], []

        for f in spec.fields:
            dtype = np.dtype(_PRIMITIVES[f.type])
            align = min(dtype.itemsize, 8)
            pad = (pos + align - 1) // align * align - pos
            pos += pad + dtype.itemsize * f.count
            if f.count == 1:
                fmt.append(f"{pad}x{_STRUCT_CODES[f.type]}" if pad else _STRUCT_CODES[f.type])
                names.append(f.name)
                continue
            close_scalars()
            pad_before = b"\0" * pad
            segments.append((_ARRAY, f.name, dtype, f.count, pad_before))
        close_scalars()
        self._segments = tuple(segments)

    def encode(self, source: object) -> bytes | None:
        """The message, or ``None`` if a value is not plainly of its field's type."""
        parts = [CDR_HEADER]
        ndarray = np.ndarray
        try:
            for kind, a, b, count, pad in self._segments:
                if kind == _ARRAY:
                    value = getattr(source, a)
                    if type(value) is not ndarray or value.size != count or value.dtype != b:
                        return None
                    if pad:
                        parts.append(pad)
                    parts.append(value.tobytes())
                else:
                    parts.append(a.pack(*[getattr(source, name) for name in b]))
        except (struct.error, TypeError, OverflowError):
            return None
        return b"".join(parts)
