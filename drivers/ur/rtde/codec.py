"""Pure codec of RTDE protocol version 2 packages (no I/O, no state but :class:`Framer`'s).

Written from Universal Robots' public "Real-Time Data Exchange (RTDE) Guide".
Every package is a 3-byte header and a payload, big-endian:

====== ====== ==========================================================
offset type   field
====== ====== ==========================================================
0      uint16 package size in bytes, header included
2      uint8  package type (an ASCII letter, :class:`PackageType`)
3      ...    payload
====== ====== ==========================================================

Payloads, client -> controller and controller -> client:

=== ======================= ================================ ==================================
    package                 from the client                  from the controller
=== ======================= ================================ ==================================
V   request protocol ver.   uint16 version                   uint8 accepted (1) / refused (0)
v   get URControl version   (none)                           uint32 major, minor, bugfix, build
M   text message            uint8 n, n chars message,        the same
                            uint8 m, m chars source,
                            uint8 warning level
U   data package            uint8 recipe id, input fields    uint8 recipe id, output fields
O   setup outputs           double frequency [Hz],           uint8 recipe id, comma-separated
                            comma-separated names            types (NOT_FOUND for unknown names)
I   setup inputs            comma-separated names            uint8 recipe id, comma-separated
                                                             types (NOT_FOUND, IN_USE)
S   start                   (none)                           uint8 accepted
P   pause                   (none)                           uint8 accepted
=== ======================= ================================ ==================================

:func:`encode` turns any message below into its bytes; :func:`decode_from_client`
and :func:`decode_from_controller` turn one package's type and payload back
into a message, and raise :class:`~drivers.errors.MalformedPacketError`
(``truncated``, ``oversized``, ``bad_value``, ``unknown_type``,
``unknown_recipe``) for anything else, naming the package's source.
:class:`Framer` cuts a TCP byte stream into packages.

ur_rtde's setup packages end their name list with a comma (``"a,b,"``): one
empty last name, which :func:`split_names` drops.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Mapping
from dataclasses import dataclass
from enum import IntEnum
from typing import Final

import numpy as np

from drivers.errors import MalformedPacketError, PacketEncodeError
from drivers.ur.rtde.fields import Recipe

HEADER: Final = struct.Struct(">HB")
HEADER_SIZE: Final = HEADER.size
MAX_PACKAGE_SIZE: Final = 0xFFFF
PROTOCOL_VERSION: Final = 2

_U8 = struct.Struct(">B")
_U16 = struct.Struct(">H")
_F64 = struct.Struct(">d")
_VERSION = struct.Struct(">IIII")


class PackageType(IntEnum):
    """The package types of the RTDE Guide (the ASCII code of each letter)."""

    REQUEST_PROTOCOL_VERSION = 86  # 'V'
    GET_URCONTROL_VERSION = 118  # 'v'
    TEXT_MESSAGE = 77  # 'M'
    DATA_PACKAGE = 85  # 'U'
    CONTROL_PACKAGE_SETUP_OUTPUTS = 79  # 'O'
    CONTROL_PACKAGE_SETUP_INPUTS = 73  # 'I'
    CONTROL_PACKAGE_START = 83  # 'S'
    CONTROL_PACKAGE_PAUSE = 80  # 'P'


class MessageLevel(IntEnum):
    """Warning levels of a text message."""

    EXCEPTION = 0
    ERROR = 1
    WARNING = 2
    INFO = 3


_TYPES: Final = frozenset(int(t) for t in PackageType)

# ----------------------------------------------------------------------------- messages


@dataclass(frozen=True, slots=True)
class RequestProtocolVersion:
    """``V`` from the client."""

    version: int


@dataclass(frozen=True, slots=True)
class GetControllerVersion:
    """``v`` from the client."""


@dataclass(frozen=True, slots=True)
class SetupOutputs:
    """``O`` from the client: output frequency and variable names."""

    frequency_hz: float
    names: tuple[str, ...]
    trailing_comma: bool = False


@dataclass(frozen=True, slots=True)
class SetupInputs:
    """``I`` from the client: input variable names."""

    names: tuple[str, ...]
    trailing_comma: bool = False


@dataclass(frozen=True, slots=True)
class Start:
    """``S`` from the client."""


@dataclass(frozen=True, slots=True)
class Pause:
    """``P`` from the client."""


@dataclass(frozen=True, slots=True)
class TextMessage:
    """``M`` either way."""

    message: str
    source: str
    level: int = MessageLevel.INFO


@dataclass(frozen=True, slots=True)
class DataPackage:
    """``U`` either way: the recipe id and the fields as a 0-d record of its recipe."""

    recipe_id: int
    record: np.ndarray


@dataclass(frozen=True, slots=True)
class Accepted:
    """The controller's answer to ``V``, ``S`` or ``P``."""

    request: PackageType
    accepted: bool


@dataclass(frozen=True, slots=True)
class ControllerVersion:
    """The controller's answer to ``v``."""

    major: int
    minor: int
    bugfix: int
    build: int

    def __str__(self) -> str:
        return f"{self.major}.{self.minor}.{self.bugfix}.{self.build}"


@dataclass(frozen=True, slots=True)
class RecipeReply:
    """The controller's answer to ``O`` or ``I``: recipe id and one type per variable."""

    request: PackageType
    recipe_id: int
    types: tuple[str, ...]


ClientMessage = (RequestProtocolVersion | GetControllerVersion | SetupOutputs | SetupInputs
                 | Start | Pause | TextMessage | DataPackage)
ControllerMessage = Accepted | ControllerVersion | RecipeReply | TextMessage | DataPackage
Message = ClientMessage | ControllerMessage

# ----------------------------------------------------------------------------- encoding


def package(ptype: int, payload: bytes = b"") -> bytes:
    """Header + payload; :class:`~drivers.errors.PacketEncodeError` past 65535 bytes."""
    size = HEADER_SIZE + len(payload)
    if size > MAX_PACKAGE_SIZE:
        raise PacketEncodeError(f"package {chr(ptype)!r}",
                                f"{size} bytes exceed the uint16 size field")
    return HEADER.pack(size, ptype) + payload


def _short_text(field: str, text: str) -> bytes:
    """A text message field: uint8 length, then that many UTF-8 bytes."""
    raw = text.encode("utf-8")
    if len(raw) > 255:
        raise PacketEncodeError(field, f"{len(raw)} bytes exceed the uint8 length field")
    return _U8.pack(len(raw)) + raw


def _ascii_text(field: str, text: str) -> bytes:
    """A setup field: ASCII to the end of the package."""
    try:
        return text.encode("ascii")
    except UnicodeEncodeError:
        raise PacketEncodeError(field, f"{text!r} is not ASCII") from None


def _names(field: str, names: tuple[str, ...], trailing_comma: bool) -> bytes:
    for name in names:
        if not name or "," in name:
            raise PacketEncodeError(field, f"bad variable name {name!r}")
    return _ascii_text(field, ",".join(names) + ("," if trailing_comma else ""))


def encode(msg: Message) -> bytes:
    """The bytes of ``msg`` on the wire, header included."""
    if isinstance(msg, DataPackage):
        if not 0 <= msg.recipe_id <= 255:
            raise PacketEncodeError("U.recipe_id", f"{msg.recipe_id} is outside uint8")
        return package(PackageType.DATA_PACKAGE, _U8.pack(msg.recipe_id) + msg.record.tobytes())
    if isinstance(msg, RequestProtocolVersion):
        if not 0 <= msg.version <= 0xFFFF:
            raise PacketEncodeError("V.version", f"{msg.version} is outside uint16")
        return package(PackageType.REQUEST_PROTOCOL_VERSION, _U16.pack(msg.version))
    if isinstance(msg, GetControllerVersion):
        return package(PackageType.GET_URCONTROL_VERSION)
    if isinstance(msg, SetupOutputs):
        return package(PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS,
                       _F64.pack(msg.frequency_hz)
                       + _names("O.variable_names", msg.names, msg.trailing_comma))
    if isinstance(msg, SetupInputs):
        return package(PackageType.CONTROL_PACKAGE_SETUP_INPUTS,
                       _names("I.variable_names", msg.names, msg.trailing_comma))
    if isinstance(msg, Start):
        return package(PackageType.CONTROL_PACKAGE_START)
    if isinstance(msg, Pause):
        return package(PackageType.CONTROL_PACKAGE_PAUSE)
    if isinstance(msg, TextMessage):
        if not 0 <= msg.level <= 255:
            raise PacketEncodeError("M.warning_level", f"{msg.level} is outside uint8")
        return package(PackageType.TEXT_MESSAGE,
                       _short_text("M.message", msg.message)
                       + _short_text("M.source", msg.source) + _U8.pack(msg.level))
    if isinstance(msg, Accepted):
        return package(msg.request, _U8.pack(1 if msg.accepted else 0))
    if isinstance(msg, ControllerVersion):
        for name in ("major", "minor", "bugfix", "build"):
            if not 0 <= getattr(msg, name) <= 0xFFFFFFFF:
                raise PacketEncodeError(f"v.{name}", "outside uint32")
        return package(PackageType.GET_URCONTROL_VERSION,
                       _VERSION.pack(msg.major, msg.minor, msg.bugfix, msg.build))
    if isinstance(msg, RecipeReply):
        if not 0 <= msg.recipe_id <= 255:
            raise PacketEncodeError(f"{chr(msg.request)}.recipe_id", "outside uint8")
        return package(msg.request, _U8.pack(msg.recipe_id)
                       + _ascii_text("variable_types", ",".join(msg.types)))
    raise PacketEncodeError(type(msg).__name__, "not an RTDE message")


# ----------------------------------------------------------------------------- decoding


def _exact(source: object, what: str, payload: bytes, size: int) -> None:
    n = len(payload)
    if n != size:
        raise MalformedPacketError(source, "truncated" if n < size else "oversized",
                                   f"{what} has {n} payload bytes, needs {size}")


def _ascii(source: object, what: str, raw: bytes) -> str:
    try:
        return raw.decode("ascii")
    except UnicodeDecodeError:
        raise MalformedPacketError(source, "bad_value", f"{what} is not ASCII") from None


def split_names(text: str) -> tuple[tuple[str, ...], bool]:
    """Variable names of a setup package and whether the list ended with a comma.

    An empty text is no names; one trailing comma (ur_rtde sends ``"a,b,"``)
    is dropped; any other empty name is kept (the controller answers NOT_FOUND).
    """
    if not text:
        return (), False
    parts = text.split(",")
    if parts[-1] == "" and len(parts) > 1:
        return tuple(parts[:-1]), True
    return tuple(parts), False


def _accepted(source: object, request: PackageType, payload: bytes) -> Accepted:
    _exact(source, f"answer to {chr(request)!r}", payload, 1)
    if payload[0] > 1:
        raise MalformedPacketError(source, "bad_value",
                                   f"answer to {chr(request)!r} is {payload[0]}, not 0 or 1")
    return Accepted(request, payload[0] == 1)


def _text_message(source: object, payload: bytes) -> TextMessage:
    n = len(payload)
    if n < 3:
        raise MalformedPacketError(source, "truncated", f"text message has {n} bytes")
    mlen = payload[0]
    if n < 1 + mlen + 1:
        raise MalformedPacketError(source, "truncated", "text message shorter than its length")
    slen = payload[1 + mlen]
    need = 1 + mlen + 1 + slen + 1
    _exact(source, "text message", payload, need)
    message = payload[1:1 + mlen].decode("utf-8", errors="replace")
    src = payload[2 + mlen:2 + mlen + slen].decode("utf-8", errors="replace")
    return TextMessage(message, src, payload[need - 1])


def _data(source: object, payload: bytes, recipes: Mapping[int, Recipe]) -> DataPackage:
    if not payload:
        raise MalformedPacketError(source, "truncated", "data package without recipe id")
    recipe = recipes.get(payload[0])
    if recipe is None:
        raise MalformedPacketError(source, "unknown_recipe",
                                   f"data package for recipe {payload[0]}, not set up")
    return DataPackage(payload[0], recipe.decode(memoryview(payload)[1:], source))


def _unknown(source: object, ptype: int, side: str) -> MalformedPacketError:
    what = f"{chr(ptype)!r} ({ptype})" if 32 <= ptype < 127 else str(ptype)
    return MalformedPacketError(source, "unknown_type", f"package type {what} from the {side}")


def decode_from_client(ptype: int, payload: bytes, input_recipes: Mapping[int, Recipe],
                       source: object = None) -> ClientMessage:
    """The message a client sent (what a controller receives)."""
    if ptype == PackageType.DATA_PACKAGE:
        return _data(source, payload, input_recipes)
    if ptype == PackageType.REQUEST_PROTOCOL_VERSION:
        _exact(source, "'V' request", payload, 2)
        return RequestProtocolVersion(_U16.unpack(payload)[0])
    if ptype == PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS:
        if len(payload) < 8:
            raise MalformedPacketError(source, "truncated",
                                       f"'O' request has {len(payload)} bytes, needs 8 or more")
        names, comma = split_names(_ascii(source, "'O' variable names", payload[8:]))
        return SetupOutputs(_F64.unpack_from(payload)[0], names, comma)
    if ptype == PackageType.CONTROL_PACKAGE_SETUP_INPUTS:
        names, comma = split_names(_ascii(source, "'I' variable names", payload))
        return SetupInputs(names, comma)
    if ptype == PackageType.TEXT_MESSAGE:
        return _text_message(source, payload)
    for kind, cls in ((PackageType.GET_URCONTROL_VERSION, GetControllerVersion),
                      (PackageType.CONTROL_PACKAGE_START, Start),
                      (PackageType.CONTROL_PACKAGE_PAUSE, Pause)):
        if ptype == kind:
            _exact(source, f"{chr(kind)!r} request", payload, 0)
            return cls()
    raise _unknown(source, ptype, "client")


def decode_from_controller(ptype: int, payload: bytes, output_recipes: Mapping[int, Recipe],
                           source: object = None) -> ControllerMessage:
    """The message a controller sent (what a client receives)."""
    if ptype == PackageType.DATA_PACKAGE:
        return _data(source, payload, output_recipes)
    if ptype in (PackageType.REQUEST_PROTOCOL_VERSION, PackageType.CONTROL_PACKAGE_START,
                 PackageType.CONTROL_PACKAGE_PAUSE):
        return _accepted(source, PackageType(ptype), payload)
    if ptype == PackageType.GET_URCONTROL_VERSION:
        _exact(source, "controller version", payload, _VERSION.size)
        return ControllerVersion(*_VERSION.unpack(payload))
    if ptype in (PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS,
                 PackageType.CONTROL_PACKAGE_SETUP_INPUTS):
        if not payload:
            raise MalformedPacketError(source, "truncated", f"answer to {chr(ptype)!r} is empty")
        text = _ascii(source, f"answer to {chr(ptype)!r}", payload[1:])
        types = tuple(text.split(",")) if text else ()
        return RecipeReply(PackageType(ptype), payload[0], types)
    if ptype == PackageType.TEXT_MESSAGE:
        return _text_message(source, payload)
    raise _unknown(source, ptype, "controller")


def frequency_ok(frequency_hz: float, max_hz: float) -> bool:
    """An output frequency a controller of base rate ``max_hz`` can serve."""
    return math.isfinite(frequency_hz) and 0.0 < frequency_hz <= max_hz


# ----------------------------------------------------------------------------- framing


class Framer:
    """Cuts a byte stream into packages: :meth:`feed` bytes, then :meth:`next` until None.

    Pure (the caller does the reading). A header whose size is below the
    header's own 3 bytes cannot be framed past: :class:`~drivers.errors.MalformedPacketError`
    (``bad_size``), after which the stream is lost.
    """

    def __init__(self, source: object = None) -> None:
        self.source = source
        self._buf = bytearray()
        self._pos = 0

    @property
    def pending(self) -> int:
        """Bytes received that do not yet make a whole package."""
        return len(self._buf) - self._pos

    def pending_need(self) -> int:
        """Bytes the partial package at the head of the buffer needs in all (0: none)."""
        if self.pending < HEADER_SIZE:
            return HEADER_SIZE if self.pending else 0
        return int(_U16.unpack_from(self._buf, self._pos)[0])

    def feed(self, data: bytes | bytearray | memoryview) -> None:
        if self._pos and self._pos == len(self._buf):
            self._buf.clear()
            self._pos = 0
        elif self._pos > 65536:
            del self._buf[:self._pos]
            self._pos = 0
        self._buf += data

    def next(self) -> tuple[int, bytes] | None:
        """The next whole package as (type, payload), or None until more bytes come."""
        avail = len(self._buf) - self._pos
        if avail < HEADER_SIZE:
            return None
        size, ptype = HEADER.unpack_from(self._buf, self._pos)
        if size < HEADER_SIZE:
            raise MalformedPacketError(self.source, "bad_size",
                                       f"package size {size} is below the 3-byte header")
        if avail < size:
            return None
        start = self._pos + HEADER_SIZE
        self._pos += size
        return ptype, bytes(self._buf[start:self._pos])

    @staticmethod
    def known(ptype: int) -> bool:
        """Whether ``ptype`` is one of the guide's package types."""
        return ptype in _TYPES
