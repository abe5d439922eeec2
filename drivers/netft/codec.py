"""Pure codec for the ATI Net F/T Raw Data Transfer (RDT) protocol over UDP.

* Request (client -> sensor port 49152), 8 bytes big-endian:
  ``uint16 0x1234, uint16 command, uint32 sample_count`` (0 = infinite).
* Response: one or more 36-byte big-endian records
  ``uint32 rdt_sequence, uint32 ft_sequence, uint32 status, int32 Fx, Fy, Fz, Tx, Ty, Tz``;
  buffered mode packs 1 to 40 records into one datagram.

Counts are converted to SI with the box's counts-per-force / counts-per-torque
and its configured units (:class:`Calibration`). The wire order
``Fx, Fy, Fz, Tx, Ty, Tz`` is already our wrench order; the frame (sensor
frame, sign of the reading) is the driver's business, not the codec's.

No I/O and no global state; decoding is a fixed number of numpy calls per
datagram, whatever the number of records.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from enum import IntEnum, IntFlag
from typing import Final, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from drivers.counters import OutcomeCounts
from drivers.errors import MalformedPacketError, PacketEncodeError

__all__ = [
    "DEFAULT_PORT",
    "FORCE_UNIT_TO_N",
    "MAX_RECORDS",
    "RECORD_DTYPE",
    "RECORD_SIZE",
    "REQUEST_DTYPE",
    "REQUEST_HEADER",
    "REQUEST_SIZE",
    "STATUS_WARNING_ONLY",
    "TORQUE_UNIT_TO_NM",
    "BytesLike",
    "Calibration",
    "RdtCommand",
    "RdtDecodeStats",
    "RdtDecodeStatus",
    "RdtRequest",
    "RdtSamples",
    "StatusBit",
    "check_rdt",
    "counts_to_si",
    "decode_rdt",
    "decode_rdt_into",
    "decode_request",
    "describe_status",
    "encode_rdt",
    "encode_request",
    "rdt_seq_delta",
    "si_to_counts",
    "status_is_error",
]

#: A datagram as received: ``bytes``, ``bytearray`` or a byte ``memoryview``.
BytesLike = bytes | bytearray | memoryview

#: UDP port of the sensor's RDT server.
DEFAULT_PORT: Final = 49152
REQUEST_HEADER: Final = 0x1234
REQUEST_SIZE: Final = 8
RECORD_SIZE: Final = 36
#: Most records one buffered-mode datagram carries ("RDT buffer size" 1..40).
MAX_RECORDS: Final = 40

REQUEST_DTYPE: Final = np.dtype([("header", ">u2"), ("command", ">u2"), ("sample_count", ">u4")])
RECORD_DTYPE: Final = np.dtype(
    [
        ("rdt_sequence", ">u4"),
        ("ft_sequence", ">u4"),
        ("status", ">u4"),
        ("Fx", ">i4"),
        ("Fy", ">i4"),
        ("Fz", ">i4"),
        ("Tx", ">i4"),
        ("Ty", ">i4"),
        ("Tz", ">i4"),
    ]
)
assert REQUEST_DTYPE.itemsize == REQUEST_SIZE and RECORD_DTYPE.itemsize == RECORD_SIZE

_REQUEST: Final = struct.Struct(">HHI")
_INT32_MIN: Final = -(2**31)
_INT32_MAX: Final = 2**31 - 1


class RdtCommand(IntEnum):
    """RDT request commands."""

    STOP = 0x0000
    START_REALTIME = 0x0002
    START_BUFFERED = 0x0003
    MULTI_UNIT = 0x0004
    RESET_LATCH = 0x0041
    SET_BIAS = 0x0042


class RdtRequest(NamedTuple):
    """A decoded RDT request."""

    command: RdtCommand
    sample_count: int


def encode_request(command: RdtCommand, sample_count: int = 0) -> bytes:
    """The 8-byte request; ``sample_count`` 0 streams until :attr:`RdtCommand.STOP`.

    Raises:
        PacketEncodeError: ``sample_count`` is not a uint32.
    """
    if not 0 <= sample_count <= 0xFFFFFFFF:
        raise PacketEncodeError("sample_count", f"{sample_count} is not a uint32")
    return _REQUEST.pack(REQUEST_HEADER, int(RdtCommand(command)), sample_count)


def decode_request(buf: BytesLike, *, source: object = None) -> RdtRequest:
    """Decode a request (the emulator side).

    Raises:
        MalformedPacketError: not 8 bytes (``"wrong_size"``), header not 0x1234
            (``"wrong_header"``) or a command this codec does not know
            (``"unknown_command"``); the message names ``source``.
    """
    n = _nbytes(buf)
    if n != REQUEST_SIZE:
        raise MalformedPacketError(
            source, "wrong_size", f"RDT request is {n} bytes, expected {REQUEST_SIZE}"
        )
    header, command, count = _REQUEST.unpack_from(buf)
    if header != REQUEST_HEADER:
        raise MalformedPacketError(
            source, "wrong_header", f"RDT request header is 0x{header:04x}, expected 0x1234"
        )
    try:
        cmd = RdtCommand(command)
    except ValueError:
        raise MalformedPacketError(
            source, "unknown_command", f"RDT request has unknown command 0x{command:04x}"
        ) from None
    return RdtRequest(cmd, count)


# --------------------------------------------------------------------------- status word


class StatusBit(IntFlag):
    """Named bits of the record's status word (0 = healthy)."""

    ERROR_SUMMARY = 0x80000000
    CPU_RAM = 0x40000000
    DIGITAL_BOARD = 0x20000000
    ANALOG_BOARD = 0x10000000
    SERIAL_LINK = 0x08000000
    PROGRAM_MEMORY = 0x04000000
    HALTED_CONFIG = 0x02000000
    SETTINGS_VALIDATION = 0x01000000
    CONFIG_CAL_MISMATCH = 0x00800000
    NETWORK_FAILURE = 0x00400000
    CAN = 0x00200000
    RDT_COMM_ERROR = 0x00100000
    ETHERNET_IP = 0x00080000
    DEVICENET = 0x00040000
    SATURATION_AD = 0x00020000
    MONITOR_LATCHED = 0x00010000


_STATUS_TEXT: Final = {
    StatusBit.ERROR_SUMMARY: "error summary",
    StatusBit.CPU_RAM: "CPU/RAM",
    StatusBit.DIGITAL_BOARD: "digital board",
    StatusBit.ANALOG_BOARD: "analog board",
    StatusBit.SERIAL_LINK: "serial link",
    StatusBit.PROGRAM_MEMORY: "program memory",
    StatusBit.HALTED_CONFIG: "halted (config)",
    StatusBit.SETTINGS_VALIDATION: "settings validation",
    StatusBit.CONFIG_CAL_MISMATCH: "config/calibration mismatch",
    StatusBit.NETWORK_FAILURE: "network failure",
    StatusBit.CAN: "CAN",
    StatusBit.RDT_COMM_ERROR: "RDT comm error",
    StatusBit.ETHERNET_IP: "EtherNet/IP",
    StatusBit.DEVICENET: "DeviceNet",
    StatusBit.SATURATION_AD: "saturation or A/D error",
    StatusBit.MONITOR_LATCHED: "monitor condition latched",
}

#: The one non-zero status that is only a warning: error summary + monitor latched.
STATUS_WARNING_ONLY: Final = int(StatusBit.ERROR_SUMMARY | StatusBit.MONITOR_LATCHED)


def describe_status(status: int) -> list[str]:
    """Names of the set bits, most significant first; ``[]`` for a healthy 0.

    Bits 0x8000..0x0001 have no confirmed individual meaning (watchdog, stack,
    EEPROM, flash, excitation current, supplies, temperature, HTTP live
    there); they are named ``"diagnostic bit 0x...."``.
    """
    s = int(status) & 0xFFFFFFFF
    names: list[str] = []
    for bit in range(31, -1, -1):
        mask = 1 << bit
        if s & mask:
            text = _STATUS_TEXT.get(StatusBit(mask)) if mask >= 0x10000 else None
            names.append(text if text is not None else f"diagnostic bit 0x{mask:04x}")
    return names


def status_is_error(status: int) -> bool:
    """True for any non-zero status except :data:`STATUS_WARNING_ONLY` (a latched monitor)."""
    s = int(status)
    return s != 0 and s != STATUS_WARNING_ONLY


def rdt_seq_delta(new: int, old: int) -> int:
    """Wrapped difference of two uint32 RDT sequence numbers, in ``[-2**31, 2**31 - 1]``."""
    return ((int(new) - int(old) + 0x80000000) & 0xFFFFFFFF) - 0x80000000


# --------------------------------------------------------------------------- records


class RdtDecodeStatus(IntEnum):
    """Outcome of checking a response datagram."""

    OK = 0
    EMPTY = 1
    NOT_MULTIPLE = 2  # length not a multiple of 36
    TOO_MANY = 3  # more than MAX_RECORDS records


class RdtDecodeStats(OutcomeCounts[RdtDecodeStatus]):
    """Counts of response datagrams per :class:`RdtDecodeStatus`, and of records accepted."""

    __slots__ = ("records",)
    outcomes = RdtDecodeStatus

    def __init__(self) -> None:
        super().__init__()
        self.records = 0

    def add(self, status: RdtDecodeStatus, records: int = 0) -> None:
        """Count one datagram with outcome ``status`` carrying ``records`` records."""
        self.counts[status] += 1
        self.records += records

    def as_dict(self) -> dict[str, int]:
        """``{"ok": n, "empty": n, ..., "records": n}`` for logs."""
        return {**super().as_dict(), "records": self.records}

    def reset(self) -> None:
        """Set every count to zero."""
        super().reset()
        self.records = 0


def _nbytes(buf: BytesLike) -> int:
    return buf.nbytes if type(buf) is memoryview else len(buf)


_OK, _EMPTY, _NOT_MULTIPLE, _TOO_MANY = (
    RdtDecodeStatus.OK,
    RdtDecodeStatus.EMPTY,
    RdtDecodeStatus.NOT_MULTIPLE,
    RdtDecodeStatus.TOO_MANY,
)


def check_rdt(buf: BytesLike) -> tuple[RdtDecodeStatus, int]:
    """Check a response datagram's length; return the status and the number of records."""
    n = _nbytes(buf)
    count, rest = divmod(n, RECORD_SIZE)
    if n == 0:
        return _EMPTY, 0
    if rest:
        return _NOT_MULTIPLE, 0
    if count > MAX_RECORDS:
        return _TOO_MANY, 0
    return _OK, count


@dataclass(eq=False, slots=True)
class RdtSamples:
    """Decoded records, in native byte order.

    ``rdt_seq``, ``ft_seq``, ``status``: uint32 (n,); ``counts``: int32 (n, 6)
    in wire order ``Fx, Fy, Fz, Tx, Ty, Tz``. All four are views of one
    native (capacity, 9) uint32 block, :attr:`words`. A buffer made by
    :meth:`empty` holds up to ``capacity`` records; :meth:`valid` trims to the
    :attr:`n` filled ones.
    """

    words: NDArray[np.uint32]
    n: int
    rdt_seq: NDArray[np.uint32] = field(init=False)
    ft_seq: NDArray[np.uint32] = field(init=False)
    status: NDArray[np.uint32] = field(init=False)
    counts: NDArray[np.int32] = field(init=False)

    def __post_init__(self) -> None:
        w = self.words
        if w.dtype != np.uint32 or w.ndim != 2 or w.shape[1] != 9:
            raise ValueError(f"words must be native uint32 (k, 9), got {w.dtype}{w.shape}")
        self.rdt_seq = w[:, 0]
        self.ft_seq = w[:, 1]
        self.status = w[:, 2]
        self.counts = w[:, 3:].view(np.int32)

    @classmethod
    def empty(cls, capacity: int = MAX_RECORDS) -> RdtSamples:
        """A preallocated buffer for :func:`decode_rdt_into`."""
        return cls(np.zeros((capacity, 9), np.uint32), 0)

    def valid(self) -> RdtSamples:
        """Views of the first :attr:`n` records (no copy)."""
        return RdtSamples(self.words[: self.n], self.n)


_BE_U4: Final = np.dtype(">u4")


def _wire_words(buf: BytesLike, count: int) -> NDArray[np.uint32]:
    return np.frombuffer(buf, _BE_U4, count * 9).reshape(count, 9)


def decode_rdt(
    buf: BytesLike, *, source: object = None, stats: RdtDecodeStats | None = None
) -> RdtSamples:
    """Decode a response datagram of 1..40 records into new native arrays.

    Raises:
        MalformedPacketError: empty, not a multiple of 36 bytes, or more than
            40 records; the message names ``source``.
    """
    status, count = check_rdt(buf)
    if stats is not None:
        stats.add(status, count)
    if status is not _OK:
        n = _nbytes(buf)
        raise MalformedPacketError(
            source,
            status.name.lower(),
            f"RDT datagram is {n} bytes; expected 36 x k bytes with 1 <= k <= {MAX_RECORDS}",
        )
    return RdtSamples(_wire_words(buf, count).astype(np.uint32), count)


def decode_rdt_into(
    buf: BytesLike, out: RdtSamples, *, stats: RdtDecodeStats | None = None
) -> RdtDecodeStatus:
    """Check a response datagram and, if valid, fill ``out`` (from :meth:`RdtSamples.empty`).

    Never raises for bad input; a rejected datagram sets ``out.n = 0``.
    Raises ``ValueError`` only if ``out`` is smaller than the datagram.
    """
    status, count = check_rdt(buf)
    if stats is not None:
        stats.add(status, count)
    if status is not _OK:
        out.n = 0
        return status
    if count > out.words.shape[0]:
        raise ValueError(f"out holds {out.words.shape[0]} records, datagram has {count}")
    out.words[:count] = _wire_words(buf, count)
    out.n = count
    return status


def encode_rdt(
    rdt_seq: ArrayLike, ft_seq: ArrayLike, status: ArrayLike, counts: ArrayLike
) -> bytes:
    """Records -> one datagram (the emulator side). Sequences wrap modulo 2**32.

    ``rdt_seq``, ``ft_seq``, ``status`` are scalars or (n,) arrays (broadcast),
    ``counts`` is (6,) or (n, 6) integer counts.

    Raises:
        PacketEncodeError: a count is outside int32 or status outside uint32, or
            there are not 1..40 records.
    """
    c = np.atleast_2d(np.asarray(counts))
    if c.ndim != 2 or c.shape[1] != 6:
        raise ValueError(f"counts must be (6,) or (n, 6), got shape {c.shape}")
    n = c.shape[0]
    if not 1 <= n <= MAX_RECORDS:
        raise PacketEncodeError("records", f"{n} records; a datagram holds 1..{MAX_RECORDS}")
    if not np.issubdtype(c.dtype, np.integer):
        raise PacketEncodeError("counts", f"need integer counts, got {c.dtype}")
    if c.size and (c.min() < _INT32_MIN or c.max() > _INT32_MAX):
        raise PacketEncodeError("counts", "outside int32; use si_to_counts to saturate")
    st = np.broadcast_to(np.asarray(status), (n,))
    if not np.issubdtype(st.dtype, np.integer) or st.min() < 0 or st.max() > 0xFFFFFFFF:
        raise PacketEncodeError("status", "need uint32 status words")
    rec = np.empty(n, RECORD_DTYPE)
    rec["rdt_sequence"] = np.broadcast_to(np.asarray(rdt_seq, np.int64) & 0xFFFFFFFF, (n,))
    rec["ft_sequence"] = np.broadcast_to(np.asarray(ft_seq, np.int64) & 0xFFFFFFFF, (n,))
    rec["status"] = st
    ints = rec.view(">i4").reshape(n, 9)
    ints[:, 3:] = c
    return rec.tobytes()


# --------------------------------------------------------------------------- scaling

#: Force unit codes (READCALINFO / netftapi2 ``scfgfu``) -> newtons per unit.
FORCE_UNIT_TO_N: Final[dict[int, float]] = {
    1: 4.4482216152605,  # lbf
    2: 1.0,  # N
    3: 4448.2216152605,  # klbf
    4: 1000.0,  # kN
    5: 9.80665,  # kg (kilogram-force)
    6: 0.00980665,  # g (gram-force)
}
#: Torque unit codes (``scfgtu``) -> newton metres per unit.
TORQUE_UNIT_TO_NM: Final[dict[int, float]] = {
    1: 4.4482216152605 * 0.0254,  # lbf·in
    2: 4.4482216152605 * 0.3048,  # lbf·ft
    3: 1.0,  # N·m
    4: 0.001,  # N·mm
    5: 9.80665 * 0.01,  # kgf·cm
    6: 1000.0,  # kN·m
}


@dataclass(frozen=True, slots=True)
class Calibration:
    """How a box scales its counts: ``SI = counts / counts_per_unit * unit_factor``.

    Args:
        counts_per_force: counts per force unit (``cfgcpf``).
        counts_per_torque: counts per torque unit (``cfgcpt``).
        force_unit: newtons per force unit of the box (1.0 for N).
        torque_unit: newton metres per torque unit (1.0 for N·m, 0.001 for N·mm).
    """

    counts_per_force: float = 1_000_000.0
    counts_per_torque: float = 1_000_000.0
    force_unit: float = 1.0
    torque_unit: float = 1.0
    scale: NDArray[np.float64] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for name in ("counts_per_force", "counts_per_torque", "force_unit", "torque_unit"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"Calibration.{name} must be a positive finite number, got {v}")
        f = self.force_unit / self.counts_per_force
        t = self.torque_unit / self.counts_per_torque
        scale = np.array([f, f, f, t, t, t])
        scale.flags.writeable = False
        object.__setattr__(self, "scale", scale)

    @classmethod
    def from_unit_codes(
        cls, counts_per_force: float, counts_per_torque: float, force_code: int, torque_code: int
    ) -> Calibration:
        """Build from ATI unit codes (force 2 = N, torque 3 = N·m, 4 = N·mm, ...)."""
        try:
            fu, tu = FORCE_UNIT_TO_N[force_code], TORQUE_UNIT_TO_NM[torque_code]
        except KeyError as exc:
            raise ValueError(f"unknown ATI unit code {exc.args[0]}") from None
        return cls(counts_per_force, counts_per_torque, fu, tu)


def counts_to_si(
    counts: ArrayLike, cal: Calibration, out: NDArray[np.float64] | None = None
) -> NDArray[np.float64]:
    """Counts (``...x6``, order Fx..Tz) -> wrench ``[fx, fy, fz, tx, ty, tz]`` in N and N·m."""
    c = np.asarray(counts)
    if c.shape[-1:] != (6,):
        raise ValueError(f"counts: last axis must have 6 entries, got shape {c.shape}")
    if out is None:
        return c * cal.scale
    np.multiply(c, cal.scale, out=out)
    return out


def si_to_counts(wrench: ArrayLike, cal: Calibration) -> NDArray[np.int32]:
    """Wrench (N, N·m; ``...x6``) -> int32 counts, rounded half to even, saturated to int32.

    Raises:
        PacketEncodeError: a value is NaN (infinities saturate).
    """
    w = np.asarray(wrench, dtype=np.float64)
    if w.shape[-1:] != (6,):
        raise ValueError(f"wrench: last axis must have 6 entries, got shape {w.shape}")
    if np.isnan(w).any():
        raise PacketEncodeError("counts", "wrench contains NaN")
    limit = cal.scale * 2.0**32  # clip first: no overflow in the division, inf saturates
    c = np.rint(np.clip(w, -limit, limit) / cal.scale)
    np.clip(c, _INT32_MIN, _INT32_MAX, out=c)
    return c.astype(np.int32)
