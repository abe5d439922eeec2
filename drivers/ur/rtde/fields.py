"""RTDE field types and recipes as numpy structured dtypes (pure: no I/O, no state).

The RTDE Guide (Universal Robots, "Real-Time Data Exchange (RTDE) Guide")
names ten field types; every one is big-endian on the wire, packed with no
padding:

============== ======================= =====
type           numpy                   bytes
============== ======================= =====
BOOL           ``?`` (0 or 1)          1
UINT8          ``u1``                  1
UINT32         ``>u4``                 4
UINT64         ``>u8``                 8
INT32          ``>i4``                 4
DOUBLE         ``>f8``                 8
VECTOR3D       ``>f8`` x 3             24
VECTOR6D       ``>f8`` x 6             48
VECTOR6INT32   ``>i4`` x 6             24
VECTOR6UINT32  ``>u4`` x 6             24
============== ======================= =====

A **recipe** is the ordered list of variables a client set up (``O`` for
outputs, ``I`` for inputs) with the types the controller answered. A data
package (``U``) is the recipe id (uint8) followed by the fields in recipe
order; :class:`Recipe` turns the fields into a 0-d numpy record (zero-copy
over the received bytes) and back.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Final

import numpy as np

from drivers.errors import MalformedPacketError, PacketEncodeError

#: Each field type of the guide: its numpy base type and its element count.
FIELD_TYPES: Final[dict[str, tuple[str, int]]] = {
    "BOOL": ("?", 1),
    "UINT8": ("u1", 1),
    "UINT32": (">u4", 1),
    "UINT64": (">u8", 1),
    "INT32": (">i4", 1),
    "DOUBLE": (">f8", 1),
    "VECTOR3D": (">f8", 3),
    "VECTOR6D": (">f8", 6),
    "VECTOR6INT32": (">i4", 6),
    "VECTOR6UINT32": (">u4", 6),
}

#: What the controller answers in place of a type for a variable it does not know.
NOT_FOUND: Final = "NOT_FOUND"
#: What it answers for an input variable another client (or a fieldbus) holds.
IN_USE: Final = "IN_USE"

#: The range of each integer type, for encoding checks.
_INT_RANGES: Final[dict[str, tuple[int, int]]] = {
    "UINT8": (0, 2**8 - 1),
    "UINT32": (0, 2**32 - 1),
    "UINT64": (0, 2**64 - 1),
    "INT32": (-(2**31), 2**31 - 1),
    "VECTOR6INT32": (-(2**31), 2**31 - 1),
    "VECTOR6UINT32": (0, 2**32 - 1),
}


def field_dtype(type_name: str) -> np.dtype[np.void]:
    """A one-field structured dtype for ``type_name`` (``KeyError`` if unknown)."""
    base, count = FIELD_TYPES[type_name]
    shape: tuple[int, ...] = () if count == 1 else (count,)
    return np.dtype([("v", base, shape)])


def field_size(type_name: str) -> int:
    """Bytes of one field of ``type_name`` on the wire."""
    base, count = FIELD_TYPES[type_name]
    return np.dtype(base).itemsize * count


@dataclass(frozen=True)
class Recipe:
    """One set-up recipe: id, variable names, their types, and the data package layout.

    ``dtype`` is the packed big-endian layout of the fields that follow the
    recipe id in a ``U`` package; ``size`` its byte count.
    """

    recipe_id: int
    names: tuple[str, ...]
    types: tuple[str, ...]
    dtype: np.dtype[np.void] = field(init=False, repr=False, compare=False)
    size: int = field(init=False, repr=False, compare=False)
    _bools: tuple[tuple[str, int], ...] = field(init=False, repr=False, compare=False)
    _doubles: np.ndarray = field(init=False, repr=False, compare=False)
    """The byte positions of every double (each field's value after value), in order:
    one finiteness check of a whole record."""

    def __post_init__(self) -> None:
        if not 0 <= self.recipe_id <= 255:
            raise PacketEncodeError("recipe_id", f"{self.recipe_id} is outside uint8")
        if len(self.names) != len(self.types):
            raise PacketEncodeError(
                "recipe", f"{len(self.names)} names but {len(self.types)} types")
        if len(set(self.names)) != len(self.names):
            raise PacketEncodeError("recipe", "a variable is named twice")
        parts: list[tuple[str, str] | tuple[str, str, tuple[int, ...]]] = []
        for name, type_name in zip(self.names, self.types, strict=True):
            if type_name not in FIELD_TYPES:
                raise PacketEncodeError(f"recipe.{name}", f"unknown field type {type_name!r}")
            base, count = FIELD_TYPES[type_name]
            parts.append((name, base) if count == 1 else (name, base, (count,)))
        dtype: np.dtype[np.void] = np.dtype(parts)
        object.__setattr__(self, "dtype", dtype)
        object.__setattr__(self, "size", dtype.itemsize)
        bools = tuple((n, dtype.fields[n][1]) for n, t in zip(self.names, self.types, strict=True)
                      if t == "BOOL") if dtype.fields else ()
        object.__setattr__(self, "_bools", bools)
        starts = [dtype.fields[n][1] + 8 * k
                  for n, t in zip(self.names, self.types, strict=True)
                  if FIELD_TYPES[t][0] == ">f8" for k in range(FIELD_TYPES[t][1])] \
            if dtype.fields else []
        object.__setattr__(self, "_doubles",
                           (np.asarray(starts, dtype=np.intp)[:, None] + np.arange(8)).ravel())

    def decode(self, data: bytes | memoryview, source: object = None) -> np.ndarray:
        """The fields of one data package (after its recipe id) as a 0-d read-only record.

        Raises :class:`~drivers.errors.MalformedPacketError` (``truncated`` or
        ``oversized``) when ``data`` is not exactly :attr:`size` bytes, and
        ``bad_value`` for a BOOL that is neither 0 nor 1.
        """
        n = len(data)
        if n != self.size:
            reason = "truncated" if n < self.size else "oversized"
            raise MalformedPacketError(
                source, reason,
                f"data package of recipe {self.recipe_id} has {n} field bytes, "
                f"its recipe needs {self.size}")
        record = np.frombuffer(data, dtype=self.dtype, count=1).reshape(())
        for name, offset in self._bools:
            if data[offset] > 1:
                raise MalformedPacketError(source, "bad_value", f"BOOL {name} is neither 0 nor 1")
        return record

    def empty(self) -> np.ndarray:
        """A writable zeroed 0-d record of this recipe (to fill and :meth:`encode`)."""
        return np.zeros((), dtype=self.dtype)

    def encode(self, values: Mapping[str, object] | np.ndarray) -> bytes:
        """The field bytes of a data package (without header or recipe id).

        ``values`` is a record of :attr:`dtype` or a mapping with every name of
        the recipe. Refuses (:class:`~drivers.errors.PacketEncodeError`) a
        missing name, a value of the wrong shape, an integer outside its type,
        and NaN or infinite doubles (nothing non-finite goes to a controller;
        a controller's own outputs may carry them, so :meth:`encode_outputs`
        allows them).
        """
        return self._encode(values, finite=True)

    def encode_outputs(self, values: Mapping[str, object] | np.ndarray) -> bytes:
        """As :meth:`encode`, but NaN and infinities pass (a controller's outputs)."""
        return self._encode(values, finite=False)

    def _encode(self, values: Mapping[str, object] | np.ndarray, *, finite: bool) -> bytes:
        if isinstance(values, np.ndarray):
            if values.dtype != self.dtype:
                raise PacketEncodeError("recipe", "record of another recipe's layout")
            data = values.tobytes()
            if finite and not np.isfinite(
                    np.frombuffer(data, np.uint8)[self._doubles].view(">f8")).all():
                for name, type_name in zip(self.names, self.types, strict=True):
                    _check_finite(name, type_name, values[name])  # names the field
            return data
        record = self.empty()
        for name, type_name in zip(self.names, self.types, strict=True):
            if name not in values:
                raise PacketEncodeError(name, "no value given")
            record[name] = _checked(name, type_name, values[name], finite=finite)
        return record.tobytes()


def _check_finite(name: str, type_name: str, value: object) -> None:
    if FIELD_TYPES[type_name][0] == ">f8" and not np.all(np.isfinite(np.asarray(value))):
        raise PacketEncodeError(name, "NaN or infinite value")


def _checked(name: str, type_name: str, value: object, *, finite: bool) -> object:
    """``value`` ready to store in a field of ``type_name``, or PacketEncodeError."""
    base, count = FIELD_TYPES[type_name]
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as exc:
        raise PacketEncodeError(name, f"not a {type_name}: {exc}") from None
    if arr.shape != (() if count == 1 else (count,)):
        raise PacketEncodeError(name, f"{type_name} needs {count} value(s), got shape {arr.shape}")
    if type_name == "BOOL":
        if arr.dtype != np.bool_ and not (
                arr.dtype.kind in "iu" and np.all((arr == 0) | (arr == 1))):
            raise PacketEncodeError(name, f"BOOL must be a bool or 0/1, got {value!r}")
        return arr.astype(bool)
    if base == ">f8":
        if arr.dtype.kind not in "iuf" or arr.dtype == np.bool_:
            raise PacketEncodeError(name, f"{type_name} must be numbers, got {arr.dtype}")
        if finite and not np.all(np.isfinite(arr)):
            raise PacketEncodeError(name, "NaN or infinite value")
        return arr.astype(np.float64)
    if arr.dtype.kind not in "iu" or arr.dtype == np.bool_:
        raise PacketEncodeError(name, f"{type_name} must be integers, got {arr.dtype}")
    lo, hi = _INT_RANGES[type_name]
    if arr.size and (int(arr.min()) < lo or int(arr.max()) > hi):
        raise PacketEncodeError(name, f"value outside {type_name} [{lo}, {hi}]")
    return arr
