"""mcap's ``Writer`` with a faster way in for messages: :class:`FastWriter`.

:meth:`FastWriter.add_message` (and :meth:`FastWriter.add_messages`, a cycle's
messages at one log time) writes the very same bytes as mcap's own (record,
chunk index, message index, statistics) with one ``struct.pack`` per message
instead of mcap's field-by-field record writer, and hands a whole chunk's
messages to mcap's chunk builder at once; :meth:`FastWriter.add_fixed` frames a
run of same-sized messages of one channel (numpy records) in one numpy array.
:meth:`FastWriter.add_cycle`, :meth:`FastWriter.add_rows`, :meth:`FastWriter.add_at`
and :meth:`FastWriter.add_series` (what the :class:`~ffexp.recording.Recorder` uses)
hold the messages and frame those of many cycles at once
(:class:`~ffexp.recording.held.Held`: the cycles of one topic tuple from one
template, the index entries per channel by numpy): the same bytes again.
A full zstd chunk is compressed in a worker thread while the next one fills. It
uses the ``Writer``'s private chunk builder, statistics and record builder; if a
future mcap lacks them, it falls
back to mcap's own ways (``tests/test_recording_writer.py`` checks that both
write identical files).
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from functools import cache
from itertools import chain
from typing import IO, Any

import numpy as np
import zstandard
from mcap.opcode import Opcode
from mcap.records import Chunk, ChunkIndex, MessageIndex
from mcap.writer import CompressionType, IndexType, Writer
from numpy.typing import NDArray

from ffexp.recording.held import (
    HEAD_DTYPE,
    HELD_MESSAGES,
    MESSAGE_FIXED,
    MESSAGE_HEAD,
    OPCODE_MESSAGE,
    Held,
    encode_rows,
)

__all__ = ["FastWriter", "encode_rows"]

_MESSAGE_HEAD = MESSAGE_HEAD
_MESSAGE_FIXED = MESSAGE_FIXED
_OPCODE_MESSAGE = OPCODE_MESSAGE
_NO_TIME = 1 << 64  # above every log time (uint64)
#: A Message Index record's head: opcode, record length, channel id, entries' length.
_INDEX_HEAD = struct.Struct("<BQHI")
_OPCODE_MESSAGE_INDEX = int(Opcode.MESSAGE_INDEX)


@cache
def _record_dtype(data_size: int) -> np.dtype[Any]:
    """A whole Message record with ``data_size`` bytes of data, as a packed numpy record
    (the fields of :data:`_MESSAGE_HEAD`, then the data)."""
    return np.dtype([*HEAD_DTYPE.descr, ("data", f"V{data_size}")])


def _compress(data: bytes, crcs: bool) -> tuple[bytes, int]:
    """A chunk's zstd compression (``zstandard.compress``, as mcap's ``Writer``) and CRC."""
    return zstandard.compress(data), (zlib.crc32(data) if crcs else 0)


@dataclass
class _MessageIndex(MessageIndex):
    """mcap's ``MessageIndex`` whose entries are kept packed, 16 bytes each (log time,
    offset; :meth:`add`), and written with them (the same bytes as its own
    field-by-field ``write``; ``records`` stays empty)."""

    packed: list[bytes] = field(default_factory=list)

    def add(self, entries: list[tuple[int, int]] | NDArray[np.uint64]) -> None:
        """Entries ``(log time, offset)``: a list, or a ``(k, 2)`` little-endian uint64 array."""
        if isinstance(entries, np.ndarray):
            self.packed.append(entries.tobytes())
        else:
            self.packed.append(struct.pack(f"<{2 * len(entries)}Q",
                                           *chain.from_iterable(entries)))

    def write(self, stream: Any) -> None:
        data = b"".join(self.packed)
        stream.write(_INDEX_HEAD.pack(_OPCODE_MESSAGE_INDEX, 6 + len(data), self.channel_id,
                                      len(data)))
        stream.write(data)


class FastWriter(Writer):
    """``mcap.writer.Writer`` with a faster :meth:`add_message` (same bytes).

    Messages are kept in a pending batch (record bytes, per-channel index
    entries, time range, counts) and handed to mcap's chunk builder and
    statistics in one go when the chunk is full or before any other call of
    the ``Writer``; the chunk is closed after the very message after which
    mcap's own writer would close it, so the files are identical. Everything
    else (schemas, channels, chunking, compression, indexes, summary) is
    mcap's. ``fast`` is False when this mcap has not the private state used.
    """

    def __init__(self, output: IO[bytes], **kw: Any) -> None:
        super().__init__(output, **kw)
        chunks = getattr(self, "_Writer__chunk_builder", None)
        stats = getattr(self, "_Writer__statistics", None)
        finalize = getattr(self, "_Writer__finalize_chunk", None)
        chunk_size = getattr(self, "_Writer__chunk_size", None)
        buffer = getattr(getattr(chunks, "record_writer", None), "_buffer", None)
        self.fast = (chunks is not None and stats is not None and callable(finalize)
                     and buffer is not None and hasattr(chunks, "message_indices")
                     and isinstance(chunk_size, int))
        self._chunks: Any = chunks
        self._stats: Any = stats
        self._finalize: Any = finalize
        self._chunk_size = chunk_size if isinstance(chunk_size, int) else 0
        # a full chunk is compressed in a worker thread (zstd and the CRC release the
        # GIL) while the next one fills; its records reach the file before anything else
        self._rb: Any = getattr(self, "_Writer__record_builder", None)
        self._stream: Any = getattr(self, "_Writer__stream", None)
        self._flush_rb: Any = getattr(self, "_Writer__flush", None)
        self._chunk_indices: Any = getattr(self, "_Writer__chunk_indices", None)
        self._index_types: Any = getattr(self, "_Writer__index_types", None)
        self._crcs = bool(getattr(self, "_Writer__enable_crcs", True))
        self.background = (self.fast and self._rb is not None and self._stream is not None
                           and callable(self._flush_rb) and self._chunk_indices is not None
                           and self._index_types is not None
                           and getattr(self, "_Writer__compression", None) == CompressionType.ZSTD)
        self._pool: ThreadPoolExecutor | None = None
        self._closing: tuple[Any, ...] | None = None  # the chunk being compressed
        # the pending batch: record bytes, per channel [(log time, offset)], counts
        self._parts: list[bytes | memoryview] = []
        # per channel its (log time, offset) entries: a list, or a (k, 2) array (_drain)
        self._index: dict[int, Any] = {}  # their lengths: the channels' counts
        self._size = 0  # the chunk's size with the pending records
        self._t_min = 0
        self._t_max = 0
        # messages held for a time-batched framing (add_cycle, add_at, add_series,
        # add_rows), and what the chunk takes first
        self._held = Held()
        self._held_room = 0
        self._counts: dict[int, int] = {}  # per channel: sequence numbers handed out

    def add_message(self, channel_id: int, log_time: int, data: bytes, publish_time: int,
                    sequence: int = 0) -> None:
        if self._held.count:
            self._drain()
        if not self.fast:
            super().add_message(channel_id, log_time, data, publish_time, sequence)
            return
        parts = self._parts
        if parts:
            if log_time < self._t_min:
                self._t_min = log_time
            elif log_time > self._t_max:
                self._t_max = log_time
        else:
            self._size = self._chunks.record_writer._buffer.tell()
            self._t_min = self._t_max = log_time
        index = self._index.get(channel_id)
        if index is None:
            index = self._index[channel_id] = []
        offset = self._size
        index.append((log_time, offset))
        parts.append(_MESSAGE_HEAD.pack(_OPCODE_MESSAGE, _MESSAGE_FIXED + len(data), channel_id,
                                        sequence, log_time, publish_time))
        parts.append(data)
        self._size = offset + _MESSAGE_HEAD.size + len(data)
        if self._size > self._chunk_size:  # mcap's rule, after the message
            self._commit()
            self._close_chunk()

    def add_messages(self, channel_ids: list[int], log_times: list[int], datas: list[bytes],
                     sequences: list[int]) -> None:
        """:meth:`add_message` for several messages (publish time = log time), in order:
        the same bytes, one call."""
        if self._held.count:
            self._drain()
        if not self.fast:
            for cid, t, data, seq in zip(channel_ids, log_times, datas, sequences, strict=True):
                super().add_message(cid, t, data, t, seq)
            return
        parts, indices = self._parts, self._index
        if parts:
            size, t_min, t_max = self._size, self._t_min, self._t_max
        else:
            size, t_min, t_max = self._chunks.record_writer._buffer.tell(), _NO_TIME, -1
        append = parts.append
        pack, head, limit = _MESSAGE_HEAD.pack, _MESSAGE_HEAD.size, self._chunk_size
        for cid, t, data, seq in zip(channel_ids, log_times, datas, sequences, strict=True):
            if t < t_min:
                t_min = t
            if t > t_max:
                t_max = t
            index = indices.get(cid)
            if index is None:
                index = indices[cid] = []
            index.append((t, size))
            n = len(data)
            append(pack(_OPCODE_MESSAGE, _MESSAGE_FIXED + n, cid, seq, t, t))
            append(data)
            size += head + n
            if size > limit:  # mcap's rule, after each message
                self._size, self._t_min, self._t_max = size, t_min, t_max
                self._commit()
                self._close_chunk()
                parts, indices = self._parts, self._index
                append = parts.append
                size, t_min, t_max = self._chunks.record_writer._buffer.tell(), _NO_TIME, -1
        self._size, self._t_min, self._t_max = size, t_min, t_max

    def add_messages_at(self, channel_ids: list[int], log_time: int, datas: list[bytes],
                        sequences: list[int]) -> None:
        """:meth:`add_messages` of messages all at one log time (a cycle's topics): the
        same bytes, without a time per message."""
        if self._held.count:
            self._drain()
        if not self.fast:
            for cid, data, seq in zip(channel_ids, datas, sequences, strict=True):
                super().add_message(cid, log_time, data, log_time, seq)
            return
        parts, indices = self._parts, self._index
        if parts:
            size = self._size
            if log_time < self._t_min:
                self._t_min = log_time
            if log_time > self._t_max:
                self._t_max = log_time
        else:
            size = self._chunks.record_writer._buffer.tell()
            self._t_min = self._t_max = log_time
        append = parts.append
        pack, head, limit = _MESSAGE_HEAD.pack, _MESSAGE_HEAD.size, self._chunk_size
        for cid, data, seq in zip(channel_ids, datas, sequences, strict=True):
            index = indices.get(cid)
            if index is None:
                index = indices[cid] = []
            index.append((log_time, size))
            n = len(data)
            append(pack(_OPCODE_MESSAGE, _MESSAGE_FIXED + n, cid, seq, log_time, log_time))
            append(data)
            size += head + n
            if size > limit:  # mcap's rule, after each message
                self._size = size
                self._commit()
                self._close_chunk()
                parts, indices = self._parts, self._index
                append = parts.append
                size = self._chunks.record_writer._buffer.tell()
                self._t_min = self._t_max = log_time  # the rest of the batch
        self._size = size

    def add_fixed(self, channel_id: int, log_times: NDArray[np.int64], first_sequence: int,
                  datas: NDArray[Any]) -> None:
        """:meth:`add_messages` of messages of one channel whose data have one size (the
        rows of a numpy record array, e.g. a cycle's F/T samples; publish time = log time,
        sequences counting up from ``first_sequence``): the same bytes, their records built
        in one numpy array instead of a ``struct.pack`` each."""
        if self._held.count:
            self._drain()
        n = len(log_times)
        size_each = datas.dtype.itemsize
        blob = np.ascontiguousarray(datas).tobytes()
        if not self.fast:
            for i, t in enumerate(log_times.tolist()):
                super().add_message(channel_id, t, blob[i * size_each:(i + 1) * size_each], t,
                                    first_sequence + i)
            return
        if n == 0:
            return
        rec = np.empty(n, dtype=_record_dtype(size_each))
        rec["op"] = _OPCODE_MESSAGE
        rec["length"] = _MESSAGE_FIXED + size_each
        rec["channel"] = channel_id
        rec["sequence"] = np.arange(first_sequence, first_sequence + n, dtype=np.int64)
        rec["log_time"] = log_times
        rec["publish_time"] = log_times
        rec["data"] = np.frombuffer(blob, dtype=rec.dtype["data"])
        records = rec.tobytes()
        times: list[int] = log_times.tolist()
        step = rec.dtype.itemsize
        done = 0
        while done < n:
            parts = self._parts
            if parts:
                size, t_min, t_max = self._size, self._t_min, self._t_max
            else:
                size, t_min, t_max = self._chunks.record_writer._buffer.tell(), _NO_TIME, -1
            # mcap closes the chunk after the first message that takes it over its size
            m = min(n - done, max(1, (self._chunk_size - size) // step + 1))
            chunk_times = times[done:done + m]
            t_min, t_max = min(t_min, *chunk_times), max(t_max, *chunk_times)
            index = self._index.get(channel_id)
            if index is None:
                index = self._index[channel_id] = []
            index.extend(zip(chunk_times, range(size, size + m * step, step), strict=True))
            parts.append(records[done * step:(done + m) * step])
            size += m * step
            self._size, self._t_min, self._t_max = size, t_min, t_max
            done += m
            if size > self._chunk_size:
                self._commit()
                self._close_chunk()

    # -- time-batched: messages held, framed many cycles at once -------------------------
    def add_cycle(self, channel_ids: Sequence[int], log_time: int,
                  datas: Sequence[bytes]) -> None:
        """A cycle's messages at one log time (publish time = log time), of the channels
        ``channel_ids``: a sequence that must not change afterwards (a run's cycles of
        the same topics give the same object). Held as :meth:`add_at`'s, the cycles of
        the same channels framed from one template (:class:`~ffexp.recording.held.Held`)."""
        if not self.fast:
            self.add_at(channel_ids, log_time, datas)
            return
        held = self._held
        if not held.count:
            self._start_holding()
        held.cycle(channel_ids, log_time, datas)
        if held.size > self._held_room or held.count >= HELD_MESSAGES:
            self._drain()

    def add_at(self, channel_ids: Sequence[int], log_time: int, datas: Sequence[bytes]) -> None:
        """Messages of several channels at one log time (publish time = log time), each
        channel's sequence numbers counting up from 0 (:meth:`reserve`).

        Held, and framed with the next cycles' at once (:meth:`_drain`) when the chunk is
        full, before any other call (a channel, :meth:`flush`, ...) or at
        :data:`~ffexp.recording.held.HELD_MESSAGES`: the file is byte for byte mcap's
        own writer's."""
        if not self.fast:
            for cid, data in zip(channel_ids, datas, strict=True):
                super().add_message(cid, log_time, data, log_time, self._next_seq(cid))
            return
        self._hold(channel_ids, [log_time] * len(datas), datas,
                   sum(map(len, datas)) + len(datas) * _MESSAGE_HEAD.size)

    def add_series(self, channel_id: int, log_times: Sequence[int],
                   datas: Sequence[bytes]) -> None:
        """Messages of one channel at their own log times (a cycle's F/T samples), held
        as :meth:`add_at`'s."""
        k = len(datas)
        if not self.fast:
            for t, data in zip(log_times, datas, strict=True):
                self.add_at((channel_id,), t, (data,))
            return
        self._hold([channel_id] * k, log_times, datas,
                   sum(map(len, datas)) + k * _MESSAGE_HEAD.size)

    def add_rows(self, channel_id: int, log_times: list[int], template: NDArray[Any],
                 columns: Mapping[str, NDArray[Any]]) -> None:
        """Messages of one channel at their own log times whose data are the rows of a
        numpy record array (``template``, one record, repeated; then each of
        ``columns`` assigned to its field, as numpy assigns), held as :meth:`add_at`'s
        and encoded at the drain for all held cycles at once. The column arrays must
        not change afterwards (give copies)."""
        if not self.fast:
            self.add_series(channel_id, log_times,
                            encode_rows(template, [columns], len(log_times)))
            return
        if not self._held.count:
            self._start_holding()
        self._held.rows(channel_id, log_times, template, columns)
        self._check_held()

    def _start_holding(self) -> None:
        """The first held message: the room left in the chunk."""
        self._held_room = self._chunk_size - (
            self._size if self._parts else self._chunks.record_writer._buffer.tell())

    def _hold(self, cids: Sequence[int], times: Sequence[int], datas: Sequence[bytes],
              size: int) -> None:
        """Hold messages (their records' ``size``); drained when the chunk they go into
        is full, or at :data:`~ffexp.recording.held.HELD_MESSAGES`."""
        if not self._held.count:
            self._start_holding()
        self._held.loose(cids, times, datas, size)
        self._check_held()

    def _check_held(self) -> None:
        held = self._held
        if held.size > self._held_room or held.count >= HELD_MESSAGES:
            self._drain()

    def reserve(self, channel_id: int, n: int) -> int:
        """The next ``n`` sequence numbers of a channel (its first), for messages given
        otherwise (:meth:`add_fixed`), after the held ones."""
        self._drain()
        return self._next_seq(channel_id, n)

    def _next_seq(self, channel_id: int, n: int = 1) -> int:
        seq = self._counts.get(channel_id, 0)
        self._counts[channel_id] = seq + n
        return seq

    def _drain(self) -> None:
        """Frame the held messages into the chunk (:meth:`Held.frame
        <ffexp.recording.held.Held.frame>`), their index entries per channel by numpy,
        the chunk closed after the very message mcap's writer would close it after."""
        if not self._held.count:
            return
        framed = self._held.frame(self._counts)
        self._commit_parts()  # what was given before them
        c, t, records = framed.channels, framed.times, framed.sizes + _MESSAGE_HEAD.size
        n = len(c)
        blob = framed.records
        done = 0
        byte = 0  # where the next message starts in blob
        while done < n:
            start = self._chunks.record_writer._buffer.tell()
            ends = np.cumsum(records[done:]) + start
            over = np.flatnonzero(ends > self._chunk_size)  # mcap's rule, after a message
            m = int(over[0]) + 1 if over.size else n - done
            seg = slice(done, done + m)
            offsets = ends[:m] - records[seg]
            # per channel (in order of first message) its (log time, offset) entries
            sc_seg = c[seg]
            o = np.argsort(sc_seg, kind="stable")
            s_sorted = sc_seg[o]
            first = np.flatnonzero(np.concatenate(([True], s_sorted[1:] != s_sorted[:-1])))
            entries = np.empty((m, 2), dtype="<u8")  # the index entries, by channel
            entries[:, 0] = t[seg][o]
            entries[:, 1] = offsets[o]
            bounds = [*first.tolist(), m]
            groups = sorted(zip(o[first].tolist(), s_sorted[first].tolist(), bounds[:-1],
                                bounds[1:], strict=True))
            self._index = {cid: entries[a:b] for _, cid, a, b in groups}
            tseg = t[seg]
            self._t_min, self._t_max = int(tseg.min()), int(tseg.max())
            size = int(ends[m - 1]) - start
            self._parts = [blob[byte:byte + size]]
            byte += size
            self._size = int(ends[m - 1])
            done += m
            self._commit_parts()
            if over.size:
                self._close_chunk()

    def _commit(self) -> None:
        """The held messages (:meth:`_drain`), then the pending batch, into the chunk."""
        if self._held.count:
            self._drain()
        self._commit_parts()

    def _commit_parts(self) -> None:
        """Hand the pending batch to mcap's chunk builder and statistics."""
        parts = self._parts
        if not parts:
            return
        st, cb = self._stats, self._chunks
        n = sum(len(records) for records in self._index.values())  # one entry a message
        t_min, t_max = self._t_min, self._t_max
        if st.message_count == 0 or t_min < st.message_start_time:
            st.message_start_time = t_min
        if t_max > st.message_end_time:
            st.message_end_time = t_max
        st.message_count += n
        counts = st.channel_message_counts
        for cid, records in self._index.items():
            counts[cid] += len(records)
        if cb.num_messages == 0 or t_min < cb.message_start_time:
            cb.message_start_time = t_min
        if t_max > cb.message_end_time:
            cb.message_end_time = t_max
        indices = cb.message_indices
        for cid, records in self._index.items():
            index = indices.get(cid)
            if index is None:
                index = indices[cid] = _MessageIndex(channel_id=cid, records=[])
            index.add(records)
        cb.num_messages += n
        cb.record_writer._buffer.write(parts[0] if len(parts) == 1 else b"".join(parts))
        self._parts = []
        self._index = {}

    def _close_chunk(self) -> None:
        """Close the full chunk as mcap's ``Writer`` does, its compression in the worker."""
        if not self.background:
            self._finalize()
            return
        self._complete()
        cb = self._chunks
        if cb.num_messages == 0:
            return
        self._stats.chunk_count += 1
        data = cb.end()
        if self._pool is None:
            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="mcap-chunk")
        self._closing = (self._pool.submit(_compress, data, self._crcs), cb.message_start_time,
                         cb.message_end_time, len(data), cb.message_indices)
        cb.message_indices = {}  # the closing chunk keeps its own
        cb.reset()

    def _complete(self) -> None:
        """Write the chunk being compressed, if any: mcap's chunk, chunk index and
        message index records, byte for byte as its ``Writer`` writes them."""
        closing = self._closing
        if closing is None:
            return
        self._closing = None
        future, start, end, size, indices = closing
        compressed, crc = future.result()
        rb, stream, flush = self._rb, self._stream, self._flush_rb
        chunk = Chunk(compression="zstd", data=compressed, message_start_time=start,
                      message_end_time=end, uncompressed_crc=crc, uncompressed_size=size)
        flush()
        chunk_start_offset = stream.tell()
        chunk.write(rb)
        chunk_index = ChunkIndex(
            message_start_time=start, message_end_time=end,
            chunk_start_offset=chunk_start_offset, chunk_length=rb.count,
            message_index_offsets={}, message_index_length=0, compression="zstd",
            compressed_size=len(compressed), uncompressed_size=size)
        flush()
        message_index_start_offset = stream.tell()
        if self._index_types & IndexType.MESSAGE:
            for cid, index in indices.items():
                chunk_index.message_index_offsets[cid] = message_index_start_offset + rb.count
                index.write(rb)
        chunk_index.message_index_length = rb.count
        flush()
        self._chunk_indices.append(chunk_index)

    # every other call of the Writer sees the pending messages first
    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        self._commit()
        self._complete()
        return int(super().register_schema(name, encoding, data))

    def register_channel(self, topic: str, message_encoding: str, schema_id: int,
                         metadata: dict[str, str] | None = None) -> int:
        self._commit()
        self._complete()
        return int(super().register_channel(topic, message_encoding, schema_id,
                                            metadata or {}))

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        self._commit()
        self._complete()
        super().add_metadata(name, data)

    def add_attachment(self, create_time: int, log_time: int, name: str, media_type: str,
                       data: bytes) -> None:
        self._commit()
        self._complete()
        super().add_attachment(create_time, log_time, name, media_type, data)

    def flush(self) -> None:
        self._commit()
        self._complete()
        super().flush()  # type: ignore[no-untyped-call]

    def finish(self) -> None:
        self._commit()
        self._complete()
        try:
            super().finish()  # type: ignore[no-untyped-call]
        finally:
            if self._pool is not None:
                self._pool.shutdown()
                self._pool = None
