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

The code lives in four modules, all re-exported here (import from here):
:mod:`~drivers.fri.codec.layout` (sizes, dtypes, enums on the wire, header
validation, records, packet buffers), :mod:`~drivers.fri.codec.fields` (field
conversions), :mod:`~drivers.fri.codec.arrays` (the arrays, decode into and
encode) and :mod:`~drivers.fri.codec.seq` (sequence counters).

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

from drivers.fri.codec.arrays import (
    CMD_ARRAY_FIELDS,
    MSR_ARRAY_FIELDS,
    MSR_SCALAR_FIELDS,
    CmdArrays,
    MsrArrays,
    cmd_arrays_from_record,
    decode_cmd_into,
    decode_msr_into,
    encode_cmd,
    encode_msr,
    msr_arrays_from_record,
    pack_cmd,
)
from drivers.fri.codec.fields import (
    cart_gains_from_wire,
    cart_gains_to_wire,
    frame_to_matrix,
    jacobian_from_wire,
    jacobian_to_wire,
    mass_matrix_from_wire,
    mass_matrix_to_wire,
    matrix_to_frame,
    wrench_from_wire,
    wrench_to_wire,
)
from drivers.fri.codec.layout import (
    CMD_BLOCK_DTYPE,
    CMD_DATAGRAM_ID,
    CMD_DTYPE,
    CMD_SIZE,
    DEFAULT_PORT,
    HEAD_DTYPE,
    INTF_DTYPE,
    INTF_STAT_DTYPE,
    KRL_DTYPE,
    MSR_DATA_DTYPE,
    MSR_DATAGRAM_ID,
    MSR_DTYPE,
    MSR_SIZE,
    NUM_JOINTS,
    ROBOT_DTYPE,
    BytesLike,
    DecodeStats,
    DecodeStatus,
    PacketBuffer,
    check_cmd,
    check_msr,
    decode_cmd,
    decode_msr,
    enum_to_wire,
    fri_control_from_wire,
    fri_quality_from_wire,
    fri_state_from_wire,
    new_cmd_buffer,
    new_msr_buffer,
)
from drivers.fri.codec.seq import SEQ_MODULUS, SeqEvent, classify_seq, seq_delta, seq_next
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
    "pack_cmd",
    "seq_delta",
    "seq_next",
    "wrench_from_wire",
    "wrench_to_wire",
]
