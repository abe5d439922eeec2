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

import keyword
import struct
from collections.abc import Callable
from functools import cache
from types import CodeType
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
        self._compiled = _compile(self._segments) or self.encode_segments

    def encode(self, source: object) -> bytes | None:
        """The message, or ``None`` if a value is not plainly of its field's type."""
        return self._compiled(source)

    def with_fallback(self, fallback: Callable[[object], bytes]) -> Callable[[object], bytes]:
        """:meth:`encode` that calls ``fallback(source)`` for its message instead of
        returning ``None`` (one call a message: the fallback compiled in)."""
        compiled = _compile(self._segments, fallback)
        if compiled is not None:
            return compiled  # type: ignore[return-value]
        encode = self.encode_segments

        def encode_or(source: object) -> bytes:
            data = encode(source)
            return fallback(source) if data is None else data
        return encode_or

    def encode_segments(self, source: object) -> bytes | None:
        """:meth:`encode` by walking the segments (the compiled form's reference)."""
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


class _Fallback(Exception):
    """A value is not plainly of its field's type (inside a compiled encoder)."""


def _compile(segments: tuple[tuple[int, Any, Any, Any, bytes], ...],
             fallback: Callable[[object], bytes] | None = None) -> Callable[
        [object], bytes | None] | None:
    """:meth:`FieldsEncoder.encode_segments` for these segments as one function of straight
    code (the same checks and parts in the same order, without the loop over segments),
    made once per message type like ``dataclasses`` makes ``__init__``. ``None`` when a
    field's name is not an identifier (the loop is kept). With ``fallback``, where it
    would return ``None`` it returns ``fallback(source)``."""
    env: dict[str, Any] = {"_nd": np.ndarray, "_head": CDR_HEADER, "_fallback": fallback,
                           "_Fallback": _Fallback,
                           "_errors": (struct.error, TypeError, OverflowError, _Fallback)}
    # a value not plainly of its type: None, or (out of the try) the fallback's message
    refuse = "return None" if fallback is None else "raise _Fallback"
    handle = "return None" if fallback is None else "return _fallback(s)"
    body: list[str] = []
    parts: list[str] = ["_head"]
    for i, (kind, a, b, count, pad) in enumerate(segments):
        names = (a,) if kind == _ARRAY else b
        if not all(str(n).isidentifier() and not keyword.iskeyword(n) for n in names):
            return None
        if kind == _ARRAY:
            env[f"_dt{i}"] = b
            body += [f"v{i} = s.{a}",
                     f"if type(v{i}) is not _nd or v{i}.size != {int(count)} "
                     f"or (v{i}.dtype is not _dt{i} and v{i}.dtype != _dt{i}):",
                     f"    {refuse}"]
            if pad:
                env[f"_pad{i}"] = pad
                parts.append(f"_pad{i}")
            parts.append(f"v{i}.tobytes()")
        else:
            env[f"_pack{i}"] = a.pack
            body.append(f"p{i} = _pack{i}({', '.join(f's.{n}' for n in b)})")
            parts.append(f"p{i}")
    code = ["def encode(s):", "    try:"]
    code += [f"        {line}" for line in body]
    code += ["    except _errors:", f"        {handle}",
             f"    return b''.join(({', '.join(parts)},))"]
    exec(_code("\n".join(code)), env)  # generated from the spec's field names only
    fn: Callable[[object], bytes | None] = env["encode"]
    return fn


@cache
def _code(source: str) -> CodeType:
    """``source`` compiled, once a process (each recorder's encoders run the same code)."""
    return compile(source, "<encoder>", "exec")
