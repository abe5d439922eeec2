"""Pure codec for the KUKA FRI 1.x (KRC2 LR) UDP packets.

Two datagrams exist, both little-endian with explicit 4-byte padding:

* the measurement packet ``tFriMsrData`` (916 bytes, datagram id 0x2006),
  sent by the KRC every cycle, and
* the command packet ``tFriCmdData`` (376 bytes, datagram id 0x1005), which the
  remote must send back within the cycle.

This module offers three levels, all free of I/O and global state:

1. **Records.** :data:`MSR_DTYPE` / :data:`CMD_DTYPE` are numpy structured dtypes
   laid out field for field as on the wire (field names as in KUKA's header).
   :func:`decode_msr` / :func:`decode_cmd` validate a datagram and return a
   zero-copy 0-d record over it; :class:`PacketBuffer` is a preallocated,
   writable record whose bytes are ready to send.
2. **Arrays in our conventions.** :class:`MsrArrays` / :class:`CmdArrays` hold
   every field of a packet as float64 numpy arrays in SI units and in the
   project's conventions (4x4 poses, wrench ``[fx, fy, fz, tx, ty, tz]``,
   Jacobian rows ``x, y, z, rx, ry, rz``, Cartesian gains ``[x, y, z, rx, ry, rz]``).
   They are allocated once; :func:`decode_msr_into` / :func:`decode_cmd_into`
   fill them from a datagram, :func:`encode_msr` / :func:`encode_cmd` turn them
   into a datagram. Both directions are a fixed number of numpy calls (one
   gather through a precomputed index), never a loop over fields.
3. **Conversions** of single fields or stacks of them: :func:`frame_to_matrix`,
   :func:`wrench_from_wire`, :func:`jacobian_from_wire`, ... and back.

Plus :class:`DecodeStats` (counts of accepted and rejected datagrams) and the
uint16 sequence helpers :func:`seq_next`, :func:`seq_delta`, :func:`classify_seq`.

Enumerations on the wire: ``intf.state`` and ``intf.quality`` are uint16 fields
that carry C enums whose INVALID member is -1. On the wire -1 is ``0xFFFF``
(two's complement truncated to 16 bits); :func:`enum_to_wire` produces that and
:func:`fri_state_from_wire` / :func:`fri_quality_from_wire` read it back. A raw
value that is no member of the enum decodes as INVALID (``ControlMode``: OTHER);
the raw value stays available (``MsrArrays.state_raw``) for logging.

Floats are IEEE float32 on the wire. Decoding widens them to float64 exactly.
Encoding rounds float64 to the nearest float32 and refuses NaN, infinities and
magnitudes above the float32 maximum (:class:`~drivers.errors.PacketEncodeError`):
a NaN in a command must never reach the robot. A signalling NaN inside a
received packet is widened to a quiet NaN; numpy may then emit a RuntimeWarning
("invalid value encountered in cast"). A real KRC sends no NaN; the decoder
checks only the header, it does not judge payload values.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from enum import IntEnum
from itertools import pairwise
from typing import Final, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

from drivers.counters import OutcomeCounts
from drivers.errors import MalformedPacketError, PacketEncodeError
from drivers.fri.types import CmdFlags, ControlMode, FriQuality, FriState

__all__ = [
    "CMD_ARRAY_FIELDS",
    "CMD_BLOCK_DTYPE",
    "CMD_DATAGRAM_ID",
    "CMD_DTYPE",
    "CMD_SIZE",
    "DEFAULT_PORT",
    "HEAD_DTYPE",
    "INTF_DTYPE",
    "INTF_STAT_DTYPE",
    "KRL_DTYPE",
    "MSR_ARRAY_FIELDS",
    "MSR_DATAGRAM_ID",
    "MSR_DATA_DTYPE",
    "MSR_DTYPE",
    "MSR_SCALAR_FIELDS",
    "MSR_SIZE",
    "NUM_JOINTS",
    "ROBOT_DTYPE",
    "SEQ_MODULUS",
    "BytesLike",
    "CmdArrays",
    "CmdFlags",
    "ControlMode",
    "DecodeStats",
    "DecodeStatus",
    "FriQuality",
    "FriState",
    "MsrArrays",
    "PacketBuffer",
    "SeqEvent",
    "cart_gains_from_wire",
    "cart_gains_to_wire",
    "check_cmd",
    "check_msr",
    "classify_seq",
    "cmd_arrays_from_record",
    "decode_cmd",
    "decode_cmd_into",
    "decode_msr",
    "decode_msr_into",
    "encode_cmd",
    "encode_msr",
    "enum_to_wire",
    "frame_to_matrix",
    "fri_control_from_wire",
    "fri_quality_from_wire",
    "fri_state_from_wire",
    "jacobian_from_wire",
    "jacobian_to_wire",
    "mass_matrix_from_wire",
    "mass_matrix_to_wire",
    "matrix_to_frame",
    "msr_arrays_from_record",
    "new_cmd_buffer",
    "new_msr_buffer",
    "seq_delta",
    "seq_next",
    "wrench_from_wire",
    "wrench_to_wire",
]

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

_U2, _I4, _U4, _F4 = "<u2", "<i4", "<u4", "<f4"
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
# the shared enums of :mod:`drivers.base.types`; this module re-exports them.


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


# --------------------------------------------------------------------------- sequence counters

SEQ_MODULUS: Final = 0x10000


def seq_next(seq: int) -> int:
    """The counter value after ``seq``: 65535 is followed by 0."""
    return (int(seq) + 1) & 0xFFFF


def seq_delta(new: int, old: int) -> int:
    """Wrapped difference ``new - old`` of two uint16 counters, in ``[-32768, 32767]``.

    1 means "the next one", 0 a duplicate, ``k > 1`` that ``k - 1`` were
    skipped, a negative value that ``new`` is older than ``old`` (reordered).
    """
    return ((int(new) - int(old) + 0x8000) & 0xFFFF) - 0x8000


class SeqEvent(IntEnum):
    """How a received counter relates to the last accepted one."""

    NEXT = 0
    DUPLICATE = 1
    GAP = 2
    STALE = 3


def classify_seq(new: int, last: int) -> tuple[SeqEvent, int]:
    """Classify ``new`` against ``last``; return the event and :func:`seq_delta`.

    For :attr:`SeqEvent.GAP` ``delta - 1`` packets are missing; for
    :attr:`SeqEvent.STALE` the packet is ``-delta`` steps older than ``last``.
    """
    d = seq_delta(new, last)
    if d == 1:
        return SeqEvent.NEXT, d
    if d == 0:
        return SeqEvent.DUPLICATE, d
    if d > 1:
        return SeqEvent.GAP, d
    return SeqEvent.STALE, d


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


def _check(buf: BytesLike, size: int, ident: int) -> DecodeStatus:
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
    return _check(buf, MSR_SIZE, MSR_DATAGRAM_ID)


def check_cmd(buf: BytesLike) -> DecodeStatus:
    """Check length, ``datagramId`` and ``packetSize`` of a command datagram."""
    return _check(buf, CMD_SIZE, CMD_DATAGRAM_ID)


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
    status = _check(buf, size, ident)
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


# --------------------------------------------------------------------------- field conversions

# Wire order of the rotational half of 6-vectors is (Z, Y, X) (FT, Jacobian
# rows, Cartesian gains A=Rz, B=Ry, C=Rx); ours is (x, y, z). The permutation
# swaps entries 3 and 5 and is its own inverse.
_ROT_PERM: Final = np.array([0, 1, 2, 5, 4, 3], dtype=np.intp)
_BOTTOM_ROW: Final = np.array([0.0, 0.0, 0.0, 1.0])


def _out_or_new(out: NDArray[np.float64] | None, shape: tuple[int, ...]) -> NDArray[np.float64]:
    if out is None:
        return np.empty(shape, dtype=np.float64)
    if out.shape != shape:
        raise ValueError(f"out has shape {out.shape}, expected {shape}")
    return out


def _last_axis(a: ArrayLike, n: int, what: str) -> NDArray[np.float64]:
    arr = np.asarray(a, dtype=np.float64)
    if arr.shape[-1:] != (n,):
        raise ValueError(f"{what}: last axis must have {n} entries, got shape {arr.shape}")
    return arr


def frame_to_matrix(
    frame: ArrayLike, out: NDArray[np.float64] | None = None
) -> NDArray[np.float64]:
    """FRI 3x4 row-major frame (12 floats, ``...x12``) -> 4x4 homogeneous matrix (``...x4x4``)."""
    f = _last_axis(frame, 12, "frame")
    res = _out_or_new(out, (*f.shape[:-1], 4, 4))
    res[..., :3, :] = f.reshape(*f.shape[:-1], 3, 4)
    res[..., 3, :] = _BOTTOM_ROW
    return res


def matrix_to_frame(
    matrix: ArrayLike, out: NDArray[np.float64] | None = None
) -> NDArray[np.float64]:
    """4x4 homogeneous matrix (``...x4x4``) -> FRI 3x4 row-major frame (``...x12``).

    The bottom row is dropped, not checked.
    """
    m = np.asarray(matrix, dtype=np.float64)
    if m.shape[-2:] != (4, 4):
        raise ValueError(f"matrix: last two axes must be 4x4, got shape {m.shape}")
    res = _out_or_new(out, (*m.shape[:-2], 12))
    res.reshape(*m.shape[:-2], 3, 4)[...] = m[..., :3, :]
    return res


def wrench_from_wire(ft: ArrayLike) -> NDArray[np.float64]:
    """Wire ``[Fx, Fy, Fz, Tz, Ty, Tx]`` -> ours ``[fx, fy, fz, tx, ty, tz]`` (``...x6``)."""
    return _last_axis(ft, 6, "wrench")[..., _ROT_PERM]


def wrench_to_wire(wrench: ArrayLike) -> NDArray[np.float64]:
    """Ours ``[fx, fy, fz, tx, ty, tz]`` -> wire ``[Fx, Fy, Fz, Tz, Ty, Tx]`` (``...x6``)."""
    return _last_axis(wrench, 6, "wrench")[..., _ROT_PERM]


def cart_gains_from_wire(gains: ArrayLike) -> NDArray[np.float64]:
    """``cartStiffness``/``cartDamping`` wire ``[x, y, z, A(Rz), B(Ry), C(Rx)]`` -> ours
    ``[x, y, z, rx, ry, rz]``."""
    return _last_axis(gains, 6, "cartesian gains")[..., _ROT_PERM]


def cart_gains_to_wire(gains: ArrayLike) -> NDArray[np.float64]:
    """Ours ``[x, y, z, rx, ry, rz]`` -> wire ``[x, y, z, A(Rz), B(Ry), C(Rx)]``."""
    return _last_axis(gains, 6, "cartesian gains")[..., _ROT_PERM]


def jacobian_from_wire(jac: ArrayLike) -> NDArray[np.float64]:
    """42 floats, row-major, rows ``X, Y, Z, RZ, RY, RX`` -> 6x7, rows ``x, y, z, rx, ry, rz``."""
    j = _last_axis(jac, 6 * _N, "jacobian")
    return j.reshape(*j.shape[:-1], 6, _N)[..., _ROT_PERM, :]


def jacobian_to_wire(jac: ArrayLike) -> NDArray[np.float64]:
    """6x7 with rows ``x, y, z, rx, ry, rz`` -> 42 wire floats (rows ``X, Y, Z, RZ, RY, RX``)."""
    j = np.asarray(jac, dtype=np.float64)
    if j.shape[-2:] != (6, _N):
        raise ValueError(f"jacobian: last two axes must be 6x{_N}, got shape {j.shape}")
    return j[..., _ROT_PERM, :].reshape(*j.shape[:-2], 6 * _N)


def mass_matrix_from_wire(mass: ArrayLike) -> NDArray[np.float64]:
    """49 floats, row-major -> 7x7."""
    m = _last_axis(mass, _N * _N, "massMatrix")
    return m.reshape(*m.shape[:-1], _N, _N).copy()


def mass_matrix_to_wire(mass: ArrayLike) -> NDArray[np.float64]:
    """7x7 -> 49 floats, row-major."""
    m = np.asarray(mass, dtype=np.float64)
    if m.shape[-2:] != (_N, _N):
        raise ValueError(f"massMatrix: last two axes must be {_N}x{_N}, got shape {m.shape}")
    return m.reshape(*m.shape[:-2], _N * _N).copy()


# --------------------------------------------------------------------------- float layouts
#
# A layout maps every float field of a packet onto one contiguous float64
# block in our conventions. Decoding copies the float words of the packet into
# a float64 scratch (at their word positions, plus the constants 0 and 1 after
# the end) and gathers the block with one ``take`` through a precomputed index;
# encoding gathers the wire words back from the block and casts them into the
# packet. The indices are derived from the dtypes above and from _ROT_PERM.

_VEC, _FRAME, _ROT6, _JAC, _MAT = "vec", "frame", "rot6", "jac", "mat"
_KIND_SHAPE: Final = {_FRAME: (4, 4), _JAC: (6, _N), _MAT: (_N, _N)}


def _field(dtype: np.dtype[np.void], path: str) -> tuple[int, int]:
    """Byte offset and size of the dotted field ``path`` in ``dtype``."""
    offset = 0
    sub: np.dtype[np.void] = dtype
    for part in path.split("."):
        assert sub.fields is not None
        sub, off = sub.fields[part][:2]
        offset += off
    return offset, sub.itemsize


def _our_to_wire_index(kind: str, n: int) -> list[int]:
    """For each entry of our (flattened) array, its index in the wire array; -1/-2 = 0.0/1.0."""
    if kind == _VEC or kind == _MAT:
        return list(range(n))
    if kind == _ROT6:
        return [int(i) for i in _ROT_PERM]
    if kind == _JAC:
        return [int(_ROT_PERM[r]) * _N + c for r in range(6) for c in range(_N)]
    if kind == _FRAME:
        return [*range(12), -1, -1, -1, -2]
    raise ValueError(kind)


class _FloatLayout:
    """Precomputed gather indices between a packet's float words and our float64 block."""

    def __init__(self, dtype: np.dtype[np.void], fields: Sequence[tuple[str, str, str]]) -> None:
        nwords = dtype.itemsize // 4
        zero, one = nwords, nwords + 1
        gather: list[int] = []
        self.slices: dict[str, tuple[slice, tuple[int, ...]]] = {}
        self.wire_path: dict[str, str] = {}
        for name, path, kind in fields:
            offset, size = _field(dtype, path)
            assert offset % 4 == 0 and size % 4 == 0
            first, n = offset // 4, size // 4
            idx = [
                first + i if i >= 0 else (zero if i == -1 else one)
                for i in _our_to_wire_index(kind, n)
            ]
            start = len(gather)
            gather.extend(idx)
            shape = _KIND_SHAPE.get(kind, (len(idx),))
            self.slices[name] = (slice(start, len(gather)), shape)
            self.wire_path[name] = path
        self.size = len(gather)
        self.nwords = nwords
        self.gather = np.array(gather, dtype=np.intp)
        # Inverse: for every wire float word, where its value sits in our block.
        inverse = np.full(nwords, -1, dtype=np.intp)
        for pos, word in enumerate(gather):
            if word < nwords:
                assert inverse[word] == -1, "a wire word is mapped twice"
                inverse[word] = pos
        words = np.flatnonzero(inverse >= 0)
        # Contiguous runs of float words, each paired with its slice of the scatter order.
        cuts = [0, *(np.flatnonzero(np.diff(words) != 1) + 1).tolist(), len(words)]
        self.run_slices = [
            (slice(int(words[a]), int(words[b - 1]) + 1), slice(a, b)) for a, b in pairwise(cuts)
        ]
        self.scatter = inverse[words]

    def view(self, block: NDArray[np.float64], name: str) -> NDArray[np.float64]:
        sl, shape = self.slices[name]
        return block[sl].reshape(shape)

    def scalar_index(self, name: str) -> int:
        sl, shape = self.slices[name]
        assert shape == (1,)
        return int(sl.start)

    def new_block(self) -> NDArray[np.float64]:
        block = np.zeros(self.size, dtype=np.float64)
        block[np.flatnonzero(self.gather == self.nwords + 1)] = 1.0
        return block

    def new_scratch(self) -> NDArray[np.float64]:
        scratch = np.zeros(self.nwords + 2, dtype=np.float64)
        scratch[self.nwords + 1] = 1.0
        return scratch

    def unpack(
        self, words: NDArray[np.float32], scratch: NDArray[np.float64], block: NDArray[np.float64]
    ) -> None:
        for wire, _ in self.run_slices:
            scratch[wire] = words[wire]
        # every index is in range; mode="wrap" only skips numpy's slower checked path
        scratch.take(self.gather, out=block, mode="wrap")

    def pack(self, block: NDArray[np.float64], words: NDArray[np.float32]) -> None:
        vals = block.take(self.scatter)
        # Fast test: a sum of squares within float32 max squared bounds every entry
        # (and is False for NaN/inf); only the rare rest needs the exact test. The
        # factor 2**-600 keeps the squares of any float64 finite: no overflow warning.
        t = vals * _RANGE_SCALE
        if not t.dot(t) <= _SCALED_F32_MAX_SQ:
            self._check_range(block, vals)
        for wire, ours in self.run_slices:
            words[wire] = vals[ours]

    def _check_range(self, block: NDArray[np.float64], vals: NDArray[np.float64]) -> None:
        bad = np.flatnonzero(~(np.abs(vals) <= _F32_MAX))
        if bad.size == 0:
            return
        pos = int(self.scatter[bad[0]])
        for name, (sl, _) in self.slices.items():
            if sl.start <= pos < sl.stop:
                raise PacketEncodeError(
                    self.wire_path[name],
                    f"{name} holds {float(block[pos])!r} (flat entry {pos - sl.start}); "
                    "must be finite and within float32 range",
                )


_F32_MAX: Final = float(np.finfo(np.float32).max)
_RANGE_SCALE: Final = 2.0**-600
_SCALED_F32_MAX_SQ: Final = (_F32_MAX * _RANGE_SCALE) ** 2

_MSR_LAYOUT: Final = _FloatLayout(
    MSR_DTYPE,
    [
        ("krl_real", "krl.realData", _VEC),
        ("timestamp", "intf.timestamp", _VEC),
        ("msr_sample_time", "intf.desiredMsrSampleTime", _VEC),
        ("cmd_sample_time", "intf.desiredCmdSampleTime", _VEC),
        ("safety_limits", "intf.safetyLimits", _VEC),
        ("answer_rate", "intf.stat.answerRate", _VEC),
        ("latency", "intf.stat.latency", _VEC),
        ("jitter", "intf.stat.jitter", _VEC),
        ("miss_rate", "intf.stat.missRate", _VEC),
        ("temperature", "robot.temperature", _VEC),
        ("msr_jnt_pos", "data.msrJntPos", _VEC),
        ("msr_cart_pos", "data.msrCartPos", _FRAME),
        ("cmd_jnt_pos", "data.cmdJntPos", _VEC),
        ("cmd_jnt_pos_fri_offset", "data.cmdJntPosFriOffset", _VEC),
        ("cmd_cart_pos", "data.cmdCartPos", _FRAME),
        ("cmd_cart_pos_fri_offset", "data.cmdCartPosFriOffset", _FRAME),
        ("msr_jnt_trq", "data.msrJntTrq", _VEC),
        ("est_ext_jnt_trq", "data.estExtJntTrq", _VEC),
        ("est_ext_tcp_ft", "data.estExtTcpFT", _ROT6),
        ("jacobian", "data.jacobian", _JAC),
        ("mass_matrix", "data.massMatrix", _MAT),
        ("gravity", "data.gravity", _VEC),
    ],
)

_CMD_LAYOUT: Final = _FloatLayout(
    CMD_DTYPE,
    [
        ("krl_real", "krl.realData", _VEC),
        ("jnt_pos", "cmd.jntPos", _VEC),
        ("cart_pos", "cmd.cartPos", _FRAME),
        ("add_jnt_trq", "cmd.addJntTrq", _VEC),
        ("add_tcp_ft", "cmd.addTcpFT", _ROT6),
        ("jnt_stiffness", "cmd.jntStiffness", _VEC),
        ("jnt_damping", "cmd.jntDamping", _VEC),
        ("cart_stiffness", "cmd.cartStiffness", _ROT6),
        ("cart_damping", "cmd.cartDamping", _ROT6),
    ],
)

#: Names of the float fields of :class:`MsrArrays` / :class:`CmdArrays` in our
#: conventions: arrays (views of ``floats``) and scalar floats. They match the
#: field names of ``drivers.base`` Measurement / Command where those exist.
MSR_ARRAY_FIELDS: Final = tuple(k for k, (_, sh) in _MSR_LAYOUT.slices.items() if sh != (1,))
MSR_SCALAR_FIELDS: Final = tuple(k for k, (_, sh) in _MSR_LAYOUT.slices.items() if sh == (1,))
CMD_ARRAY_FIELDS: Final = tuple(_CMD_LAYOUT.slices)

# Integer fields, read and written with one struct call each (pad bytes skip the floats).
# Measurement: head (4H) | krl.boolData, krl.fill | intf.state, intf.quality |
# intf.stat.missCounter | robot.power, control, error, warning.
_MSR_INTS: Final = struct.Struct("<4H128x2H4x2H28xI4H")
# Command: head (4H) | krl.boolData, krl.fill | cmd.cmdFlags.
_CMD_INTS: Final = struct.Struct("<4H128x2HI")
_KRL_INT_OFFSET: Final = _field(MSR_DTYPE, "krl.intData")[0]
assert _KRL_INT_OFFSET == _field(CMD_DTYPE, "krl.intData")[0]
_KRL_INT_WORDS: Final = slice(_KRL_INT_OFFSET // 4, _KRL_INT_OFFSET // 4 + 16)


class _Slot:
    """A scalar float field of an arrays object, stored in its float64 block."""

    __slots__ = ("index",)

    def __init__(self, index: int) -> None:
        self.index = index

    @overload
    def __get__(self, obj: None, owner: type) -> _Slot: ...
    @overload
    def __get__(self, obj: MsrArrays, owner: type) -> float: ...
    def __get__(self, obj: MsrArrays | None, owner: type) -> _Slot | float:
        if obj is None:
            return self
        return float(obj.floats[self.index])

    def __set__(self, obj: MsrArrays, value: float) -> None:
        obj.floats[self.index] = value


class MsrArrays:
    """Every field of a measurement packet, as numpy arrays in our conventions.

    Allocate once and refill each cycle with :func:`decode_msr_into`; the
    array attributes are views of one float64 block (:attr:`floats`) and keep
    their identity, so copy what must outlive the next decode. Units are SI as
    sent by the KRC (rad, m, N, N·m, s).

    Attributes (wire field in brackets):
        msr_jnt_pos (7) [data.msrJntPos], cmd_jnt_pos (7), cmd_jnt_pos_fri_offset (7),
        msr_cart_pos, cmd_cart_pos, cmd_cart_pos_fri_offset: 4x4 homogeneous,
        msr_jnt_trq (7), est_ext_jnt_trq (7), gravity (7), temperature (7),
        est_ext_tcp_ft (6): ``[fx, fy, fz, tx, ty, tz]`` (wire ``Fx..Fz, Tz, Ty, Tx``),
        jacobian (6x7): rows ``x, y, z, rx, ry, rz``, mass_matrix (7x7),
        krl_real (16) [krl.realData], krl_int (16, int32) [krl.intData],
        scalar floats (properties): timestamp, msr_sample_time,
        cmd_sample_time, safety_limits, answer_rate, latency, jitter, miss_rate,
        ints: send_seq, refl_seq, krl_bool, krl_fill, state_raw, quality_raw,
        miss_counter, power, control_raw, error, warning.
    """

    timestamp = _Slot(_MSR_LAYOUT.scalar_index("timestamp"))
    msr_sample_time = _Slot(_MSR_LAYOUT.scalar_index("msr_sample_time"))
    cmd_sample_time = _Slot(_MSR_LAYOUT.scalar_index("cmd_sample_time"))
    safety_limits = _Slot(_MSR_LAYOUT.scalar_index("safety_limits"))
    answer_rate = _Slot(_MSR_LAYOUT.scalar_index("answer_rate"))
    latency = _Slot(_MSR_LAYOUT.scalar_index("latency"))
    jitter = _Slot(_MSR_LAYOUT.scalar_index("jitter"))
    miss_rate = _Slot(_MSR_LAYOUT.scalar_index("miss_rate"))

    def __init__(self) -> None:
        lay = _MSR_LAYOUT
        self.floats: NDArray[np.float64] = lay.new_block()
        self._scratch = lay.new_scratch()
        b = self.floats
        self.krl_real = lay.view(b, "krl_real")
        self.temperature = lay.view(b, "temperature")
        self.msr_jnt_pos = lay.view(b, "msr_jnt_pos")
        self.msr_cart_pos = lay.view(b, "msr_cart_pos")
        self.cmd_jnt_pos = lay.view(b, "cmd_jnt_pos")
        self.cmd_jnt_pos_fri_offset = lay.view(b, "cmd_jnt_pos_fri_offset")
        self.cmd_cart_pos = lay.view(b, "cmd_cart_pos")
        self.cmd_cart_pos_fri_offset = lay.view(b, "cmd_cart_pos_fri_offset")
        self.msr_jnt_trq = lay.view(b, "msr_jnt_trq")
        self.est_ext_jnt_trq = lay.view(b, "est_ext_jnt_trq")
        self.est_ext_tcp_ft = lay.view(b, "est_ext_tcp_ft")
        self.jacobian = lay.view(b, "jacobian")
        self.mass_matrix = lay.view(b, "mass_matrix")
        self.gravity = lay.view(b, "gravity")
        self.krl_int: NDArray[np.int32] = np.zeros(16, dtype=np.int32)
        self.send_seq = 0
        self.refl_seq = 0
        self.krl_bool = 0
        self.krl_fill = 0
        self.state_raw = enum_to_wire(FriState.OFF)
        self.quality_raw = enum_to_wire(FriQuality.UNACCEPTABLE)
        self.miss_counter = 0
        self.power = 0
        self.control_raw = enum_to_wire(ControlMode.OTHER)
        self.error = 0
        self.warning = 0

    @property
    def state(self) -> FriState:
        """``intf.state`` as an enum (unknown raw values read as INVALID)."""
        return fri_state_from_wire(self.state_raw)

    @state.setter
    def state(self, value: FriState) -> None:
        self.state_raw = enum_to_wire(value)

    @property
    def quality(self) -> FriQuality:
        """``intf.quality`` as an enum (unknown raw values read as INVALID)."""
        return fri_quality_from_wire(self.quality_raw)

    @quality.setter
    def quality(self, value: FriQuality) -> None:
        self.quality_raw = enum_to_wire(value)

    @property
    def control(self) -> ControlMode:
        """``robot.control`` as an enum (unknown raw values read as OTHER)."""
        return fri_control_from_wire(self.control_raw)

    @control.setter
    def control(self, value: ControlMode) -> None:
        self.control_raw = enum_to_wire(value)

    def _unpack(self, buf: BytesLike) -> None:
        (
            self.send_seq,
            self.refl_seq,
            _,
            _,
            self.krl_bool,
            self.krl_fill,
            self.state_raw,
            self.quality_raw,
            self.miss_counter,
            self.power,
            self.control_raw,
            self.error,
            self.warning,
        ) = _MSR_INTS.unpack_from(buf)
        words = np.frombuffer(buf, _F4)
        self.krl_int[:] = words[_KRL_INT_WORDS].view(_I4)
        _MSR_LAYOUT.unpack(words, self._scratch, self.floats)


class CmdArrays:
    """Every field of a command packet, as numpy arrays in our conventions.

    Fill the arrays in place (``cmd.jnt_pos[:] = q``) and call :func:`encode_cmd`;
    fields keep their values between cycles. :func:`decode_cmd_into` fills it
    from a datagram (the emulator side).

    Attributes (wire field in brackets):
        jnt_pos (7, rad), cart_pos (4x4 homogeneous, m), add_jnt_trq (7, N·m),
        add_tcp_ft (6): ``[fx, fy, fz, tx, ty, tz]`` (wire ``Fx..Fz, Tz, Ty, Tx``),
        jnt_stiffness (7, N·m/rad), jnt_damping (7, normalized),
        cart_stiffness (6, N/m and N·m/rad), cart_damping (6, normalized): both
        ``[x, y, z, rx, ry, rz]`` (wire ``x, y, z, A(Rz), B(Ry), C(Rx)``),
        krl_real (16), krl_int (16, int32), krl_bool, krl_fill,
        cmd_flags (int; :attr:`flags` as :class:`CmdFlags`), send_seq, refl_seq.
    """

    def __init__(self) -> None:
        lay = _CMD_LAYOUT
        self.floats: NDArray[np.float64] = lay.new_block()
        self._scratch = lay.new_scratch()
        b = self.floats
        self.krl_real = lay.view(b, "krl_real")
        self.jnt_pos = lay.view(b, "jnt_pos")
        self.cart_pos = lay.view(b, "cart_pos")
        self.add_jnt_trq = lay.view(b, "add_jnt_trq")
        self.add_tcp_ft = lay.view(b, "add_tcp_ft")
        self.jnt_stiffness = lay.view(b, "jnt_stiffness")
        self.jnt_damping = lay.view(b, "jnt_damping")
        self.cart_stiffness = lay.view(b, "cart_stiffness")
        self.cart_damping = lay.view(b, "cart_damping")
        self.krl_int: NDArray[np.int32] = np.zeros(16, dtype=np.int32)
        self.krl_bool = 0
        self.krl_fill = 0
        self.cmd_flags = 0
        self.send_seq = 0
        self.refl_seq = 0

    @property
    def flags(self) -> CmdFlags:
        """``cmd.cmdFlags`` as :class:`CmdFlags` (unknown bits are kept)."""
        return CmdFlags(self.cmd_flags)

    @flags.setter
    def flags(self, value: CmdFlags | int) -> None:
        self.cmd_flags = int(value)

    def _unpack(self, buf: BytesLike) -> None:
        (
            self.send_seq,
            self.refl_seq,
            _,
            _,
            self.krl_bool,
            self.krl_fill,
            self.cmd_flags,
        ) = _CMD_INTS.unpack_from(buf)
        words = np.frombuffer(buf, _F4)
        self.krl_int[:] = words[_KRL_INT_WORDS].view(_I4)
        _CMD_LAYOUT.unpack(words, self._scratch, self.floats)


def decode_msr_into(
    buf: BytesLike, out: MsrArrays, *, stats: DecodeStats | None = None
) -> DecodeStatus:
    """Check a measurement datagram and, if it is valid, fill ``out`` from it.

    Never raises for bad input: a rejected datagram leaves ``out`` untouched and
    returns the reason; ``stats`` (if given) counts the outcome.
    """
    status = _check(buf, MSR_SIZE, MSR_DATAGRAM_ID)
    if stats is not None:
        stats.add(status)
    if status is _OK:
        out._unpack(buf)
    return status


def decode_cmd_into(
    buf: BytesLike, out: CmdArrays, *, stats: DecodeStats | None = None
) -> DecodeStatus:
    """Check a command datagram and, if it is valid, fill ``out`` (see :func:`decode_msr_into`)."""
    status = _check(buf, CMD_SIZE, CMD_DATAGRAM_ID)
    if stats is not None:
        stats.add(status)
    if status is _OK:
        out._unpack(buf)
    return status


def _record_bytes(record: NDArray[np.void], dtype: np.dtype[np.void]) -> bytes:
    if record.dtype != dtype or record.size != 1:
        raise ValueError(f"need one record of the packet dtype, got {record.dtype}{record.shape}")
    return record.tobytes()


def msr_arrays_from_record(record: NDArray[np.void], out: MsrArrays | None = None) -> MsrArrays:
    """Convert a :data:`MSR_DTYPE` record (e.g. from :func:`decode_msr`) to arrays."""
    res = MsrArrays() if out is None else out
    res._unpack(_record_bytes(record, MSR_DTYPE))
    return res


def cmd_arrays_from_record(record: NDArray[np.void], out: CmdArrays | None = None) -> CmdArrays:
    """Convert a :data:`CMD_DTYPE` record (e.g. from :func:`decode_cmd`) to arrays."""
    res = CmdArrays() if out is None else out
    res._unpack(_record_bytes(record, CMD_DTYPE))
    return res


# --------------------------------------------------------------------------- encoding


class PacketBuffer:
    """A preallocated, writable packet: bytes, a structured record and word views over them.

    ``raw`` is the datagram (``bytearray``), ``record`` a 0-d structured view
    of it for field access by wire name. The header's ``packetSize`` and
    ``datagramId`` are set at construction.
    """

    __slots__ = ("_f4", "_i4", "raw", "record")

    def __init__(self, dtype: np.dtype[np.void], datagram_id: int) -> None:
        self.raw = bytearray(dtype.itemsize)
        self.record: NDArray[np.void] = np.frombuffer(self.raw, dtype).reshape(())
        self.record["head"]["packetSize"] = dtype.itemsize
        self.record["head"]["datagramId"] = datagram_id
        self._f4: NDArray[np.float32] = np.frombuffer(self.raw, _F4)
        self._i4: NDArray[np.int32] = np.frombuffer(self.raw, _I4)

    def tobytes(self) -> bytes:
        """The datagram as immutable bytes (a copy)."""
        return bytes(self.raw)


def new_msr_buffer() -> PacketBuffer:
    """A zeroed measurement packet with ``packetSize`` 916 and ``datagramId`` 0x2006."""
    return PacketBuffer(MSR_DTYPE, MSR_DATAGRAM_ID)


def new_cmd_buffer() -> PacketBuffer:
    """A zeroed command packet with ``packetSize`` 376 and ``datagramId`` 0x1005."""
    return PacketBuffer(CMD_DTYPE, CMD_DATAGRAM_ID)


def _int_error(fields: Sequence[tuple[str, object, int]]) -> PacketEncodeError:
    """Name the first integer field (wire name, value, bits) that does not fit (cold path)."""
    for field, value, bits in fields:
        if not isinstance(value, int) or not 0 <= value < (1 << bits):
            return PacketEncodeError(field, f"{value!r} is not a uint{bits}")
    return PacketEncodeError("<integer field>", "does not fit its wire type")  # pragma: no cover


def encode_msr(arrays: MsrArrays, buf: PacketBuffer | None = None) -> bytes:
    """Write ``arrays`` into ``buf`` (a :func:`new_msr_buffer`) and return the datagram.

    The header's sequence counters come from ``arrays.send_seq`` / ``refl_seq``.

    Raises:
        PacketEncodeError: a float is NaN, infinite or beyond float32 range, or
            an integer does not fit its wire type.
    """
    pb = new_msr_buffer() if buf is None else buf
    if pb.record.dtype != MSR_DTYPE:
        raise ValueError("encode_msr needs a measurement PacketBuffer (new_msr_buffer())")
    a = arrays
    try:
        _MSR_INTS.pack_into(
            pb.raw, 0, a.send_seq, a.refl_seq, MSR_SIZE, MSR_DATAGRAM_ID, a.krl_bool,
            a.krl_fill, a.state_raw, a.quality_raw, a.miss_counter, a.power, a.control_raw,
            a.error, a.warning,
        )  # fmt: skip
    except struct.error as exc:
        raise _int_error(
            [
                ("head.sendSeqCount", a.send_seq, 16), ("head.reflSeqCount", a.refl_seq, 16),
                ("krl.boolData", a.krl_bool, 16), ("krl.fill", a.krl_fill, 16),
                ("intf.state", a.state_raw, 16), ("intf.quality", a.quality_raw, 16),
                ("intf.stat.missCounter", a.miss_counter, 32), ("robot.power", a.power, 16),
                ("robot.control", a.control_raw, 16), ("robot.error", a.error, 16),
                ("robot.warning", a.warning, 16),
            ]
        ) from exc  # fmt: skip
    _write_krl_int(pb, a.krl_int)
    _MSR_LAYOUT.pack(a.floats, pb._f4)
    return bytes(pb.raw)


def encode_cmd(arrays: CmdArrays, buf: PacketBuffer | None = None) -> bytes:
    """Write ``arrays`` into ``buf`` (a :func:`new_cmd_buffer`) and return the datagram.

    Set ``arrays.send_seq`` (:func:`seq_next` of the last one) and
    ``arrays.refl_seq`` (the measurement's ``send_seq``) before each call.

    Raises:
        PacketEncodeError: a float is NaN, infinite or beyond float32 range, or
            an integer does not fit its wire type.
    """
    pb = new_cmd_buffer() if buf is None else buf
    if pb.record.dtype != CMD_DTYPE:
        raise ValueError("encode_cmd needs a command PacketBuffer (new_cmd_buffer())")
    a = arrays
    try:
        _CMD_INTS.pack_into(
            pb.raw, 0, a.send_seq, a.refl_seq, CMD_SIZE, CMD_DATAGRAM_ID, a.krl_bool,
            a.krl_fill, a.cmd_flags,
        )  # fmt: skip
    except struct.error as exc:
        raise _int_error(
            [
                ("head.sendSeqCount", a.send_seq, 16), ("head.reflSeqCount", a.refl_seq, 16),
                ("krl.boolData", a.krl_bool, 16), ("krl.fill", a.krl_fill, 16),
                ("cmd.cmdFlags", a.cmd_flags, 32),
            ]
        ) from exc  # fmt: skip
    _write_krl_int(pb, a.krl_int)
    _CMD_LAYOUT.pack(a.floats, pb._f4)
    return bytes(pb.raw)


def _write_krl_int(pb: PacketBuffer, values: NDArray[np.int32]) -> None:
    if values.dtype != np.int32 or values.shape != (16,):
        raise PacketEncodeError("krl.intData", f"need int32[16], got {values.dtype}{values.shape}")
    pb._i4[_KRL_INT_WORDS] = values
