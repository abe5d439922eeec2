"""A finished recording's messages, chunk by chunk, as numpy columns (no object per message).

mcap's ``SeekingReader.iter_messages`` builds a ``Message`` (and reads each of its
fields through a stream object) for every record; a run has about 25 messages a
controller cycle, and that was most of :func:`ffexp.recording.load`'s time. Here
mcap still reads the summary, each ``Chunk`` record (one object a chunk) and
decompresses and CRC-checks the chunk's data (``get_chunk_data_stream``, as its
reader does); what is done by hand is finding the message records in that data
and gathering their fields:

- the records are located from the chunk's message indexes (the ``Message Index``
  records after the chunk, one per channel: log time and offset of each of its
  messages), parsed as numpy arrays. They are only a map: the index is used only
  if its records, with the few records it does not list (schemas, channels) walked
  in between, tile the chunk's data from its first byte to its last, exactly the
  records a walk from the start finds, so a message the index missed cannot be
  missed here. Otherwise the chunk is walked record by record (``struct`` over
  offsets, no object per record);
- channel id, log time and record length come from the message records themselves
  (not from the index), gathered for all of a chunk's messages at once;
- a channel's payloads stay where they are in the decompressed chunks: a
  fixed-size topic's are gathered into one ``(n, itemsize)`` byte array
  (:meth:`ChannelMessages.rows`), others sliced one by one (:meth:`ChannelMessages.payloads`).

The chunks are those mcap's reader would read (its chunk-index rules for topics and
times) in the summary's order, the messages in file order, so a caller sees the
very messages ``iter_messages(log_time_order=False)`` yields, in its order.
A chunk that cannot be read is a :class:`ChunkError` naming the chunk (its number
from 1 in the file's chunk index, and its byte offset) and why: its record is cut
short, its data does not decompress (zstd or lz4; :func:`decompression_failed` says
which library errors those are), its CRC does not match, or, in data whose CRC matches,
a record runs past the chunk's end or a message record is shorter than its fixed fields.
"""

from __future__ import annotations

import struct
from collections.abc import Collection
from dataclasses import dataclass, field
from typing import IO, Any

import numpy as np
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Chunk, ChunkIndex
from mcap.stream_reader import CRCValidationError, get_chunk_data_stream
from mcap.summary import Summary
from zstandard import ZstdError

__all__ = ["ChannelMessages", "ChunkError", "decompression_failed", "read_messages"]

#: A record's head: opcode, length of what follows.
_HEAD = struct.Struct("<BQ")
#: A message record's fixed fields after the head: channel id, sequence, log and publish time.
_MESSAGE_FIELDS = 2 + 4 + 8 + 8
#: Where, from a message record's start, its channel id, log time and payload are.
_AT_CHANNEL, _AT_LOG_TIME, _AT_DATA = 9, 9 + 2 + 4, 9 + _MESSAGE_FIELDS
#: A message index record's head: opcode, length, channel id, byte length of its entries.
_INDEX_HEAD = struct.Struct("<BQHI")
_INDEX_ENTRY = np.dtype([("log_time", "<u8"), ("offset", "<u8")])
#: The compressions of a chunk's records the MCAP spec names ("": none).
_COMPRESSIONS = ("", "zstd", "lz4")


class ChunkError(McapError):
    """A chunk of a finished file that cannot be read: ``number`` counts from 1 in the
    file's chunk index, ``offset`` is the chunk record's byte offset in the file."""

    def __init__(self, number: int, offset: int, reason: str) -> None:
        self.number = number
        self.offset = offset
        self.reason = reason
        super().__init__(f"chunk {number} at byte {offset}: {reason}")


def decompression_failed(exc: BaseException) -> bool:
    """Whether ``exc`` is what decompressing damaged chunk data raises: zstandard's
    ``ZstdError``, or lz4.frame's plain ``RuntimeError`` (its messages name the LZ4F
    call or say the frame is incomplete; a subclass, such as RecursionError, is a bug)."""
    if isinstance(exc, ZstdError):
        return True
    text = str(exc)
    return type(exc) is RuntimeError and ("LZ4F_" in text or text.startswith("Frame "))


@dataclass
class _Part:
    """One chunk's messages of one channel: the chunk's bytes, payload starts and sizes."""

    data: np.ndarray
    starts: np.ndarray
    sizes: np.ndarray


@dataclass
class ChannelMessages:
    """One channel's messages in file order: log times, payload sizes and the payloads,
    left in the decompressed chunks until asked for."""

    log_time_ns: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=np.int64))
    sizes: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=np.int64))
    parts: list[_Part] = field(default_factory=list)

    def __len__(self) -> int:
        return int(self.log_time_ns.shape[0])

    def rows(self, itemsize: int) -> np.ndarray:
        """The payloads as one array of ``itemsize``-byte items (numpy ``void``; every
        size must be ``itemsize``), to be viewed through a structured dtype of that size."""
        if np.any(self.sizes != itemsize):
            raise ValueError(f"not every payload is {itemsize} bytes")
        item = np.dtype((np.void, itemsize))
        blocks = [_gather(p.data, p.starts, item) for p in self.parts if len(p.starts)]
        if not blocks:
            return np.empty(0, dtype=item)
        return blocks[0] if len(blocks) == 1 else np.concatenate(blocks)

    def payloads(self) -> list[bytes]:
        """Each payload as ``bytes``, in file order."""
        out: list[bytes] = []
        for p in self.parts:
            buf = p.data.data
            out += [bytes(buf[a:a + n]) for a, n in zip(p.starts.tolist(), p.sizes.tolist(),
                                                         strict=True)]
        return out


def chunks_to_read(summary: Summary, channel_ids: Collection[int] | None,
                   start_ns: int | None, end_ns: int | None) -> list[ChunkIndex]:
    """The chunks that may hold messages of ``channel_ids`` (None: all) with
    ``start_ns <= log_time < end_ns``, in the summary's order: mcap's reader's rules (a
    chunk without message indexes may hold any channel)."""
    out = []
    for ci in summary.chunk_indexes:
        if start_ns is not None and ci.message_end_time < start_ns:
            continue
        if end_ns is not None and ci.message_start_time >= end_ns:
            continue
        if (channel_ids is not None and ci.message_index_offsets
                and not any(c in channel_ids for c in ci.message_index_offsets)):
            continue
        out.append(ci)
    return out


def read_messages(fh: IO[bytes], summary: Summary, channel_ids: Collection[int] | None,
                  start_ns: int | None = None, end_ns: int | None = None,
                  ) -> dict[int, ChannelMessages]:
    """The messages of ``channel_ids`` (None: every channel) with ``start_ns <= log_time <
    end_ns``, by channel id, each in file order. A chunk that cannot be read (cut short,
    does not decompress, a CRC that does not match, records that do not fit) raises a
    :class:`ChunkError` naming it."""
    wanted = None if channel_ids is None else np.array(sorted(channel_ids), dtype=np.int64)
    parts: dict[int, list[tuple[np.ndarray, _Part]]] = {}
    numbers = {ci.chunk_start_offset: k for k, ci in enumerate(summary.chunk_indexes, 1)}
    for ci in chunks_to_read(summary, channel_ids, start_ns, end_ns):
        number = numbers[ci.chunk_start_offset]
        data = _chunk_data(fh, ci, number)
        offsets = _indexed(data, _index_records(fh, ci), ci) if ci.message_index_offsets \
            else None
        if offsets is None:
            try:
                offsets = np.array(_walk(data, 0, len(data)), dtype=np.int64)
            except McapError as exc:
                raise ChunkError(number, ci.chunk_start_offset, str(exc)) from None
        if not len(offsets):
            continue
        u = np.frombuffer(data, dtype=np.uint8)
        length = _gather(u, offsets + 1, "<u8").astype(np.int64)
        bad = np.flatnonzero((length < _MESSAGE_FIELDS) | (offsets + 9 + length > len(data)))
        if len(bad):
            raise ChunkError(number, ci.chunk_start_offset, f"the message record at byte "
                             f"{int(offsets[bad[0]])} of its data is shorter than its fields "
                             "or runs past the chunk's end")
        cid = _gather(u, offsets + _AT_CHANNEL, "<u2").astype(np.int64)
        log_time = _gather(u, offsets + _AT_LOG_TIME, "<i8").astype(np.int64)
        keep = np.ones(len(offsets), dtype=bool) if wanted is None else np.isin(cid, wanted)
        if start_ns is not None:
            keep &= log_time >= start_ns
        if end_ns is not None:
            keep &= log_time < end_ns
        for c in np.unique(cid[keep]).tolist():
            sel = keep & (cid == c)
            parts.setdefault(c, []).append((log_time[sel], _Part(
                u, offsets[sel] + _AT_DATA, length[sel] - _MESSAGE_FIELDS)))
    out = {}
    for c, got in parts.items():
        out[c] = ChannelMessages(np.concatenate([t for t, _ in got]),
                                 np.concatenate([p.sizes for _, p in got]),
                                 [p for _, p in got])
    return out


def _chunk_data(fh: IO[bytes], ci: ChunkIndex, number: int) -> bytes:
    """The chunk's records, decompressed and CRC-checked by mcap (its reader's
    ``get_chunk_data_stream``, the same libraries and rules); a :class:`ChunkError`
    naming chunk ``number`` if it cannot be."""
    at = ci.chunk_start_offset
    fh.seek(at)
    head = fh.read(_HEAD.size)
    if len(head) < _HEAD.size or head[0] != Opcode.CHUNK:
        raise ChunkError(number, at, "the chunk index points to no chunk record")
    try:
        chunk = Chunk.read(ReadDataStream(fh))
    except (McapError, struct.error, ValueError, MemoryError) as exc:
        raise ChunkError(number, at, "its record is cut short or malformed: "
                         f"{_first_line(exc)}") from None
    if chunk.compression not in _COMPRESSIONS:  # mcap would read it as uncompressed
        raise ChunkError(number, at, f"unknown compression {chunk.compression!r}")
    try:
        stream, size = get_chunk_data_stream(chunk, validate_crc=True)
    except CRCValidationError:
        raise ChunkError(number, at, "its CRC does not match its data") from None
    except McapError as exc:  # an unknown compression
        raise ChunkError(number, at, str(exc)) from None
    except Exception as exc:
        if not isinstance(exc, MemoryError | ValueError) and not decompression_failed(exc):
            raise
        raise ChunkError(number, at, f"its {chunk.compression} data does not decompress: "
                         f"{_first_line(exc)}") from None
    return stream.read(size)


def _first_line(exc: BaseException) -> str:
    """An error's message, its first line, shortened (what a library says went wrong)."""
    text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    return text if len(text) <= 100 else text[:97] + "..."


def _index_records(fh: IO[bytes], ci: ChunkIndex) -> bytes:
    """The message index records after the chunk (``message_index_length`` bytes)."""
    fh.seek(ci.chunk_start_offset + ci.chunk_length)
    return fh.read(ci.message_index_length)


def _indexed(data: bytes, index: bytes, ci: ChunkIndex) -> np.ndarray | None:
    """The sorted offsets of the chunk's message records as its message indexes give
    them, or None if the indexes do not account for exactly the records a walk from the
    start of ``data`` finds (then the chunk is walked)."""
    base = ci.chunk_start_offset + ci.chunk_length
    offsets, channels, times = [], [], []
    for cid, where in ci.message_index_offsets.items():
        rel = where - base
        if rel < 0 or rel + _INDEX_HEAD.size > len(index):
            return None
        op, _length, channel, size = _INDEX_HEAD.unpack_from(index, rel)
        end = rel + _INDEX_HEAD.size + size
        if op != Opcode.MESSAGE_INDEX or channel != cid or size % 16 or end > len(index):
            return None
        entries = np.frombuffer(index, dtype=_INDEX_ENTRY, count=size // 16,
                                offset=rel + _INDEX_HEAD.size)
        offsets.append(entries["offset"])
        times.append(entries["log_time"])
        channels.append(np.full(len(entries), cid, dtype=np.int64))
    if not offsets:
        return None
    at_all = np.concatenate(offsets)
    order = np.argsort(at_all, kind="stable")
    at = at_all[order].astype(np.int64)
    if len(at) and (at[0] < 0 or at[-1] + _AT_DATA > len(data)
                    or np.any(np.diff(at) <= 0)):
        return None
    if not len(at):
        return at if not _walk(data, 0, len(data)) else None
    u = np.frombuffer(data, dtype=np.uint8)
    ends = at + 9 + _gather(u, at + 1, "<u8").astype(np.int64)
    if (np.any(u[at] != Opcode.MESSAGE) or ends[-1] > len(data)
            or np.any(_gather(u, at + _AT_CHANNEL, "<u2") != np.concatenate(channels)[order])
            or np.any(_gather(u, at + _AT_LOG_TIME, "<u8") != np.concatenate(times)[order])):
        return None
    gaps = np.flatnonzero(ends[:-1] != at[1:])
    if np.any(ends[gaps] > at[gaps + 1]):
        return None  # records overlap
    spans = [(0, int(at[0]))] + [(int(ends[g]), int(at[g + 1])) for g in gaps.tolist()]
    spans.append((int(ends[-1]), len(data)))
    try:
        if any(_walk(data, a, b) for a, b in spans if a < b):
            return None  # a message the index does not list
    except McapError:
        return None
    return at


def _walk(data: bytes, start: int, stop: int) -> list[int]:
    """The offsets of the message records among the records from ``start``, which must
    end exactly at ``stop`` (one ``struct`` call a record)."""
    head, found, pos = _HEAD.unpack_from, [], start
    message = int(Opcode.MESSAGE)
    while pos < stop:
        if pos + _HEAD.size > stop:
            raise McapError(f"the record at byte {pos} of its data is cut short")
        op, length = head(data, pos)
        if op == message:
            found.append(pos)
        at, pos = pos, pos + _HEAD.size + length
        if pos > stop:
            raise McapError(f"the record at byte {at} of its data runs past the chunk's end")
    return found


def _gather(u: np.ndarray, at: np.ndarray, dtype: str | np.dtype[Any]) -> np.ndarray:
    """The items of ``dtype`` that start at the byte offsets ``at`` of the bytes ``u``
    (every one within ``u``): one fancy index into a view of ``u`` with an item at every
    byte (a stride of one byte; the items overlap)."""
    dt = np.dtype(dtype)
    every = np.ndarray(shape=(len(u) - dt.itemsize + 1,), dtype=dt, buffer=u, strides=(1,))
    values: np.ndarray = every[at]
    return values
