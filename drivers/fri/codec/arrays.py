"""FRI 1.x packets as numpy arrays in our conventions: decode into, encode from.

Part of the codec (:mod:`drivers.fri.codec` documents it whole and re-exports
every public name). :class:`MsrArrays` / :class:`CmdArrays` are allocated
once; both directions are a fixed number of numpy calls through precomputed
gather indices, never a loop over fields.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from itertools import pairwise
from typing import Final, overload

import numpy as np
from numpy.typing import NDArray

from drivers.errors import PacketEncodeError
from drivers.fri.codec.fields import ROT_PERM as _ROT_PERM
from drivers.fri.codec.layout import (
    CMD_DATAGRAM_ID,
    CMD_DTYPE,
    CMD_SIZE,
    MSR_DATAGRAM_ID,
    MSR_DTYPE,
    MSR_SIZE,
    NUM_JOINTS,
    BytesLike,
    DecodeStats,
    DecodeStatus,
    PacketBuffer,
    check_datagram,
    enum_to_wire,
    fri_control_from_wire,
    fri_quality_from_wire,
    fri_state_from_wire,
    new_cmd_buffer,
    new_msr_buffer,
)
from drivers.fri.codec.layout import (
    F4 as _F4,
)
from drivers.fri.codec.layout import (
    I4 as _I4,
)
from drivers.fri.types import CmdFlags, ControlMode, FriQuality, FriState

_N = NUM_JOINTS
_OK = DecodeStatus.OK

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
#: field names of :class:`~drivers.fri.types.FriMeasurement` / ``FriCommand``
#: where those exist.
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
    status = check_datagram(buf, MSR_SIZE, MSR_DATAGRAM_ID)
    if stats is not None:
        stats.add(status)
    if status is _OK:
        out._unpack(buf)
    return status


def decode_cmd_into(
    buf: BytesLike, out: CmdArrays, *, stats: DecodeStats | None = None
) -> DecodeStatus:
    """Check a command datagram and, if it is valid, fill ``out`` (see :func:`decode_msr_into`)."""
    status = check_datagram(buf, CMD_SIZE, CMD_DATAGRAM_ID)
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
    _MSR_LAYOUT.pack(a.floats, pb.f4)
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
    pack_cmd(arrays, pb)
    return bytes(pb.raw)


def pack_cmd(arrays: CmdArrays, pb: PacketBuffer) -> None:
    """:func:`encode_cmd` without the copy: the datagram is ``pb.raw`` (no allocation).

    Raises:
        PacketEncodeError: as :func:`encode_cmd`.
    """
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
    _CMD_LAYOUT.pack(a.floats, pb.f4)


def _write_krl_int(pb: PacketBuffer, values: NDArray[np.int32]) -> None:
    if values.dtype != np.int32 or values.shape != (16,):
        raise PacketEncodeError("krl.intData", f"need int32[16], got {values.dtype}{values.shape}")
    pb.i4[_KRL_INT_WORDS] = values
