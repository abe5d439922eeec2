"""FRI 1.x packet layout: sizes, ids, numpy dtypes, enums on the wire, header validation.

Part of the codec (:mod:`drivers.fri.codec` documents it whole and re-exports
every public name). Records: :data:`MSR_DTYPE` / :data:`CMD_DTYPE` are laid
out field for field as on the wire; :func:`decode_msr` / :func:`decode_cmd`
validate a datagram and return a zero-copy record over it;
:class:`PacketBuffer` is a preallocated writable record.
"""

from __future__ import annotations

import struct
from enum import IntEnum
from typing import Final

import numpy as np
from numpy.typing import NDArray

from drivers.counters import OutcomeCounts
from drivers.errors import MalformedPacketError
from drivers.fri.types import ControlMode, FriQuality, FriState

#: A datagram as received: ``bytes``, ``bytearray`` or a byte ``memoryview``.
BytesLike = bytes | bytearray | memoryview

NUM_JOINTS: Final = 7
MSR_SIZE: Final = 916
CMD_SIZE: Final = 376
MSR_DATAGRAM_ID: Final = 0x2006
CMD_DATAGRAM_ID: Final = 0x1005
#: UDP port the remote listens on (``FRISOCK`` in the KRC's dlrrc.ini).
DEFAULT_PORT: Final = 49938

# --------------------------------------------------------------------------- dtypes

#: Wire types: little-endian uint16, int32, uint32, float32.
U2, I4, U4, F4 = "<u2", "<i4", "<u4", "<f4"
_U2, _I4, _U4, _F4 = U2, I4, U4, F4
_N = NUM_JOINTS

HEAD_DTYPE: Final = np.dtype(
    [("sendSeqCount", _U2), ("reflSeqCount", _U2), ("packetSize", _U2), ("datagramId", _U2)]
)
KRL_DTYPE: Final = np.dtype(
    [("realData", _F4, (16,)), ("intData", _I4, (16,)), ("boolData", _U2), ("fill", _U2)]
)
INTF_STAT_DTYPE: Final = np.dtype(
    [
        ("answerRate", _F4),
        ("latency", _F4),
        ("jitter", _F4),
        ("missRate", _F4),
        ("missCounter", _U4),
    ]
)
INTF_DTYPE: Final = np.dtype(
    [
        ("timestamp", _F4),
        ("state", _U2),
        ("quality", _U2),
        ("desiredMsrSampleTime", _F4),
        ("desiredCmdSampleTime", _F4),
        ("safetyLimits", _F4),
        ("stat", INTF_STAT_DTYPE),
    ]
)
ROBOT_DTYPE: Final = np.dtype(
    [
        ("power", _U2),
        ("control", _U2),
        ("error", _U2),
        ("warning", _U2),
        ("temperature", _F4, (_N,)),
    ]
)
MSR_DATA_DTYPE: Final = np.dtype(
    [
        ("msrJntPos", _F4, (_N,)),
        ("msrCartPos", _F4, (12,)),
        ("cmdJntPos", _F4, (_N,)),
        ("cmdJntPosFriOffset", _F4, (_N,)),
        ("cmdCartPos", _F4, (12,)),
        ("cmdCartPosFriOffset", _F4, (12,)),
        ("msrJntTrq", _F4, (_N,)),
        ("estExtJntTrq", _F4, (_N,)),
        ("estExtTcpFT", _F4, (6,)),
        ("jacobian", _F4, (6 * _N,)),
        ("massMatrix", _F4, (_N * _N,)),
        ("gravity", _F4, (_N,)),
    ]
)
CMD_BLOCK_DTYPE: Final = np.dtype(
    [
        ("cmdFlags", _U4),
        ("jntPos", _F4, (_N,)),
        ("cartPos", _F4, (12,)),
        ("addJntTrq", _F4, (_N,)),
        ("addTcpFT", _F4, (6,)),
        ("jntStiffness", _F4, (_N,)),
        ("jntDamping", _F4, (_N,)),
        ("cartStiffness", _F4, (6,)),
        ("cartDamping", _F4, (6,)),
    ]
)
#: ``tFriMsrData``: 916 bytes, KRC -> remote.
MSR_DTYPE: Final = np.dtype(
    [
        ("head", HEAD_DTYPE),
        ("krl", KRL_DTYPE),
        ("intf", INTF_DTYPE),
        ("robot", ROBOT_DTYPE),
        ("data", MSR_DATA_DTYPE),
    ]
)
#: ``tFriCmdData``: 376 bytes, remote -> KRC.
CMD_DTYPE: Final = np.dtype([("head", HEAD_DTYPE), ("krl", KRL_DTYPE), ("cmd", CMD_BLOCK_DTYPE)])

assert MSR_DTYPE.itemsize == MSR_SIZE and CMD_DTYPE.itemsize == CMD_SIZE

# --------------------------------------------------------------------------- enums


# FriState, FriQuality, ControlMode (``robot.control``, FRI_CTRL) and CmdFlags are
# the enums of :mod:`drivers.fri.types`; :mod:`drivers.fri.codec` re-exports them.


def enum_to_wire(value: int) -> int:
    """The uint16 that carries ``value`` on the wire: ``-1`` (INVALID) becomes ``0xFFFF``."""
    return int(value) & 0xFFFF


_STATE_BY_RAW: Final = {enum_to_wire(m): m for m in FriState}
_QUALITY_BY_RAW: Final = {enum_to_wire(m): m for m in FriQuality}
_CONTROL_BY_RAW: Final = {enum_to_wire(m): m for m in ControlMode}


def fri_state_from_wire(raw: int) -> FriState:
    """Read ``intf.state``; 0xFFFF and any unknown value give :attr:`FriState.INVALID`."""
    return _STATE_BY_RAW.get(int(raw), FriState.INVALID)


def fri_quality_from_wire(raw: int) -> FriQuality:
    """Read ``intf.quality``; 0xFFFF and any unknown value give :attr:`FriQuality.INVALID`."""
    return _QUALITY_BY_RAW.get(int(raw), FriQuality.INVALID)


def fri_control_from_wire(raw: int) -> ControlMode:
    """Read ``robot.control``; an unknown value gives :attr:`ControlMode.OTHER`."""
    return _CONTROL_BY_RAW.get(int(raw), ControlMode.OTHER)


# --------------------------------------------------------------------------- validation


class DecodeStatus(IntEnum):
    """Outcome of checking a received datagram, in the order the checks run."""

    OK = 0
    TOO_SHORT = 1
    TOO_LONG = 2
    WRONG_ID = 3
    WRONG_PACKET_SIZE = 4


class DecodeStats(OutcomeCounts[DecodeStatus]):
    """Counts of decoded datagrams per :class:`DecodeStatus`; for a driver's health report."""

    __slots__ = ()
    outcomes = DecodeStatus


_OK, _TOO_SHORT, _TOO_LONG = DecodeStatus.OK, DecodeStatus.TOO_SHORT, DecodeStatus.TOO_LONG
_WRONG_ID, _WRONG_PACKET_SIZE = DecodeStatus.WRONG_ID, DecodeStatus.WRONG_PACKET_SIZE
_SIZE_ID: Final = struct.Struct("<HH")  # head.packetSize, head.datagramId at offset 4


def _nbytes(buf: BytesLike) -> int:
    return buf.nbytes if type(buf) is memoryview else len(buf)


def check_datagram(buf: BytesLike, size: int, ident: int) -> DecodeStatus:
    """Check a datagram's length, ``datagramId`` and ``packetSize`` against a packet type."""
    n = _nbytes(buf)
    if n != size:
        return _TOO_SHORT if n < size else _TOO_LONG
    psize, did = _SIZE_ID.unpack_from(buf, 4)
    if did != ident:
        return _WRONG_ID
    if psize != size:
        return _WRONG_PACKET_SIZE
    return _OK


def check_msr(buf: BytesLike) -> DecodeStatus:
    """Check length, ``datagramId`` and ``packetSize`` of a measurement datagram."""
    return check_datagram(buf, MSR_SIZE, MSR_DATAGRAM_ID)


def check_cmd(buf: BytesLike) -> DecodeStatus:
    """Check length, ``datagramId`` and ``packetSize`` of a command datagram."""
    return check_datagram(buf, CMD_SIZE, CMD_DATAGRAM_ID)


def _error(
    status: DecodeStatus, buf: BytesLike, what: str, size: int, ident: int, source: object
) -> MalformedPacketError:
    n = _nbytes(buf)
    if status in (DecodeStatus.TOO_SHORT, DecodeStatus.TOO_LONG):
        msg = f"{what} datagram is {n} bytes, expected {size}"
    elif status is DecodeStatus.WRONG_ID:
        did = _SIZE_ID.unpack_from(buf, 4)[1]
        msg = f"{what} datagram has datagramId 0x{did:04x}, expected 0x{ident:04x}"
    else:
        psize = _SIZE_ID.unpack_from(buf, 4)[0]
        msg = f"{what} datagram has packetSize {psize}, expected {size}"
    return MalformedPacketError(source, status.name.lower(), msg)


def _decode(
    buf: BytesLike,
    dtype: np.dtype[np.void],
    what: str,
    size: int,
    ident: int,
    source: object,
    stats: DecodeStats | None,
) -> NDArray[np.void]:
    status = check_datagram(buf, size, ident)
    if stats is not None:
        stats.add(status)
    if status is not _OK:
        raise _error(status, buf, what, size, ident, source)
    return np.frombuffer(buf, dtype).reshape(())


def decode_msr(
    buf: BytesLike, *, source: object = None, stats: DecodeStats | None = None
) -> NDArray[np.void]:
    """Validate a measurement datagram and return it as a 0-d :data:`MSR_DTYPE` record.

    The record is a view of ``buf`` (no copy): it changes if ``buf`` is reused
    and is read-only for ``bytes``. ``rec["data"]["msrJntPos"]`` is a float32[7].

    Raises:
        MalformedPacketError: wrong length, ``datagramId`` or ``packetSize``;
            the message names ``source`` (an address tuple or a string).
    """
    return _decode(buf, MSR_DTYPE, "measurement", MSR_SIZE, MSR_DATAGRAM_ID, source, stats)


def decode_cmd(
    buf: BytesLike, *, source: object = None, stats: DecodeStats | None = None
) -> NDArray[np.void]:
    """Validate a command datagram and return it as a 0-d :data:`CMD_DTYPE` record view.

    Raises:
        MalformedPacketError: wrong length, ``datagramId`` or ``packetSize``.
    """
    return _decode(buf, CMD_DTYPE, "command", CMD_SIZE, CMD_DATAGRAM_ID, source, stats)


# --------------------------------------------------------------------------- buffers


class PacketBuffer:
    """A preallocated, writable packet: bytes, a structured record and word views over them.

    ``raw`` is the datagram (``bytearray``), ``record`` a 0-d structured view
    of it for field access by wire name, ``f4`` / ``i4`` its 4-byte words.
    The header's ``packetSize`` and ``datagramId`` are set at construction.
    """

    __slots__ = ("f4", "i4", "raw", "record")

    def __init__(self, dtype: np.dtype[np.void], datagram_id: int) -> None:
        self.raw = bytearray(dtype.itemsize)
        self.record: NDArray[np.void] = np.frombuffer(self.raw, dtype).reshape(())
        self.record["head"]["packetSize"] = dtype.itemsize
        self.record["head"]["datagramId"] = datagram_id
        self.f4: NDArray[np.float32] = np.frombuffer(self.raw, _F4)
        self.i4: NDArray[np.int32] = np.frombuffer(self.raw, _I4)

    def tobytes(self) -> bytes:
        """The datagram as immutable bytes (a copy)."""
        return bytes(self.raw)


def new_msr_buffer() -> PacketBuffer:
    """A zeroed measurement packet with ``packetSize`` 916 and ``datagramId`` 0x2006."""
    return PacketBuffer(MSR_DTYPE, MSR_DATAGRAM_ID)


def new_cmd_buffer() -> PacketBuffer:
    """A zeroed command packet with ``packetSize`` 376 and ``datagramId`` 0x1005."""
    return PacketBuffer(CMD_DTYPE, CMD_DATAGRAM_ID)
