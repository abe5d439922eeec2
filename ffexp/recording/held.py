"""Messages held by :class:`~ffexp.recording.mcap_writer.FastWriter` and framed many
cycles at once: :class:`Held`.

Messages come in *units* (one call: a cycle's topics, a cycle's F/T samples, an
event) and are kept in *blocks*. Every cycle of a run writes the same topics in
the same order, so a cycle's topics go to the block of their channel tuple
(:meth:`Held.cycle`): per call only its log time and its messages are kept. At
the drain (:meth:`Held.frame`) such a block's records are built at once from one
template of a cycle's records (each message's MCAP record head: opcode, record
length, channel, sequence, log and publish time; then its data): the template
repeated with the data put in, joined in one go, and only the heads' sequence
numbers and times set, through a numpy view of the bytes. The rows of a record
(:meth:`Held.rows`, the F/T samples) are one numpy array of heads and rows; the
rest (single messages, a cycle whose message sizes changed) is joined with blank
heads, put in their places by numpy. The units are then laid out in the order
they were given: the very records mcap's own writer writes message by message
(``tests/test_recording_writer.py``).

Pure: no I/O. The writer hands the records to its chunks, closing each one after
the message mcap's writer would close it after.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from operator import itemgetter
from typing import Any

import numpy as np
from mcap.opcode import Opcode
from numpy.typing import NDArray

__all__ = ["HELD_MESSAGES", "Framed", "Held", "encode_rows", "sequences"]

#: An MCAP Message record's head: opcode, record length, channel id, sequence,
#: log time, publish time (the MCAP specification's field order, little endian).
MESSAGE_HEAD = struct.Struct("<BQHIQQ")
MESSAGE_FIXED = MESSAGE_HEAD.size - 9  # the record length counts what follows it
OPCODE_MESSAGE = int(Opcode.MESSAGE)
#: :data:`MESSAGE_HEAD` as a packed numpy record (many heads in one array)
HEAD_DTYPE = np.dtype([("op", "u1"), ("length", "<u8"), ("channel", "<u2"),
                       ("sequence", "<u4"), ("log_time", "<u8"), ("publish_time", "<u8")])
_BLANK_HEAD = bytes(MESSAGE_HEAD.size)  # a head's place, filled by numpy
_HEAD_RANGE = np.arange(MESSAGE_HEAD.size, dtype=np.int64)
_first = itemgetter(0)
#: held messages drained into the chunk at the latest at this count
HELD_MESSAGES = 4096


def encode_rows(template: NDArray[Any], blocks: list[Mapping[str, NDArray[Any]]],
                n: int) -> list[bytes]:
    """Each of the ``n`` rows' bytes: ``template`` repeated, each block's columns assigned
    to their fields (numpy's casts), one message a row."""
    rec = np.repeat(template, n)
    for name in blocks[0]:
        rec[name] = np.concatenate([b[name] for b in blocks])
    return list(map(_first, struct.Struct(f"{rec.dtype.itemsize}s").iter_unpack(
        rec.tobytes())))


def sequences(c: NDArray[np.uint16], counts: dict[int, int]) -> NDArray[np.int64]:
    """Each message's sequence number, the messages' channels ``c`` in order: its
    channel's count so far (``counts``, updated) plus its rank among them."""
    n = len(c)
    order = np.argsort(c, kind="stable")
    sc = c[order]
    starts = np.flatnonzero(np.concatenate(([True], sc[1:] != sc[:-1])))
    sizes = np.diff(np.append(starts, n))
    base = []
    for cid, k in zip(sc[starts].tolist(), sizes.tolist(), strict=True):
        b = counts.get(cid, 0)
        base.append(b)
        counts[cid] = b + k
    seq = np.empty(n, dtype=np.int64)
    seq[order] = np.arange(n) - np.repeat(starts - np.asarray(base, dtype=np.int64), sizes)
    return seq


def _fill_heads(heads: NDArray[Any], c: NDArray[Any], t: NDArray[Any],
                sizes: NDArray[Any], seq: NDArray[Any]) -> NDArray[Any]:
    """Message record heads (``HEAD_DTYPE`` records) of channels ``c``, log and publish
    times ``t``, data sizes and sequences, written into ``heads``."""
    heads["op"] = OPCODE_MESSAGE
    heads["length"] = sizes + MESSAGE_FIXED
    heads["channel"] = c
    heads["sequence"] = seq
    heads["log_time"] = t
    heads["publish_time"] = t
    return heads


def _heads(c: NDArray[Any], t: NDArray[Any], sizes: NDArray[Any],
           seq: NDArray[Any]) -> NDArray[Any]:
    return _fill_heads(np.empty(len(c), dtype=HEAD_DTYPE), c, t, sizes, seq)


def _records(heads: NDArray[Any], datas: Sequence[bytes]) -> bytearray:
    """Records one by one (each message's head, then its data): the data joined with a
    blank head before each, then the heads put in their places by numpy."""
    n = len(datas)
    parts = [_BLANK_HEAD] * (2 * n)
    parts[1::2] = datas
    out = bytearray().join(parts)
    record_sizes = heads["length"].astype(np.int64) + 9  # what the length counts, + 9
    starts = np.cumsum(record_sizes) - record_sizes
    where = (starts[:, None] + _HEAD_RANGE).reshape(-1)
    np.frombuffer(out, dtype=np.uint8)[where] = heads.view(np.uint8)
    return out


class _Loose:
    """Messages of any channels, times and sizes, a unit per call."""

    def __init__(self, index: int) -> None:
        self.index = index  # in the held blocks
        self.cids: list[int] = []
        self.times: list[int] = []
        self.datas: list[bytes] = []
        self.counts: list[int] = []  # per unit, its messages

    def arrays(self) -> tuple[NDArray[Any], NDArray[Any], NDArray[Any], NDArray[Any]]:
        """Channels, log times, data sizes, messages per unit."""
        n = len(self.cids)
        return (np.array(self.cids, dtype=np.uint16), np.array(self.times, dtype=np.uint64),
                np.fromiter(map(len, self.datas), dtype=np.int64, count=n),
                np.array(self.counts, dtype=np.int64))

    def records(self, c: NDArray[Any], t: NDArray[Any], sizes: NDArray[Any],
                seq: NDArray[Any]) -> bytearray:
        return _records(_heads(c, t, sizes, seq), self.datas)


class _Rows:
    """Messages of one channel whose data are the rows of one record template with
    columns assigned (:meth:`Held.rows`), a unit per call: their records built as one
    numpy array (each a head, then the template's bytes, the columns assigned)."""

    def __init__(self, index: int, channel_id: int, template: NDArray[Any]) -> None:
        self.index = index  # in the held blocks
        self.channel = channel_id
        self.template = template
        self.times: list[int] = []
        self.counts: list[int] = []
        self.columns: list[Mapping[str, NDArray[Any]]] = []
        size = template.dtype.itemsize
        self.dtype = np.dtype({"names": ["head", "data"], "formats": [HEAD_DTYPE, template.dtype],
                               "offsets": [0, MESSAGE_HEAD.size],
                               "itemsize": MESSAGE_HEAD.size + size})

    def sequences(self, counts: dict[int, int]) -> None:
        return None

    def arrays(self) -> tuple[NDArray[Any], NDArray[Any], NDArray[Any], NDArray[Any]]:
        n = len(self.times)
        return (np.full(n, self.channel, dtype=np.uint16),
                np.array(self.times, dtype=np.uint64),
                np.full(n, self.template.dtype.itemsize, dtype=np.int64),
                np.array(self.counts, dtype=np.int64))

    def records(self, c: NDArray[Any], t: NDArray[Any], sizes: NDArray[Any],
                seq: NDArray[Any]) -> memoryview:
        """The rows' records: the bytes of :func:`encode_rows` (the template repeated,
        each column assigned to its field), each after its head."""
        n = len(c)
        rec = np.empty(n, dtype=self.dtype)
        raw = rec.view(np.uint8).reshape(n, self.dtype.itemsize)
        raw[:, MESSAGE_HEAD.size:] = np.frombuffer(self.template.tobytes(), dtype=np.uint8)
        data = rec["data"]
        for name in self.columns[0]:
            data[name] = np.concatenate([cols[name] for cols in self.columns])
        _fill_heads(rec["head"], c, t, sizes, seq)
        return raw.reshape(-1).data


class _Cycles:
    """Cycles of one channel tuple (:meth:`Held.cycle`): a unit a cycle."""

    def __init__(self, index: int, key: Sequence[int], datas: Sequence[bytes]) -> None:
        self.index = index  # in the held blocks
        self.key = key  # the caller's sequence of channels (checked by identity)
        self.cids = np.array(key, dtype=np.uint16)
        self.m = len(key)
        self.unique = len(set(key)) == self.m  # each channel once a cycle
        self.lens = list(map(len, datas))  # a cycle's data sizes (the first cycle's)
        self.sizes = np.array(self.lens, dtype=np.int64)
        self.size = int(self.sizes.sum()) + self.m * MESSAGE_HEAD.size  # a cycle's records
        self.times: list[int] = []
        self.datas: list[bytes] = []
        # a cycle's records: the heads (sequence and times 0), the data between them
        self.template: list[bytes] = []
        names: list[str] = []
        offsets: list[int] = []
        pos = 0
        for i, (cid, size) in enumerate(zip(key, self.sizes.tolist(), strict=True)):
            self.template += [MESSAGE_HEAD.pack(OPCODE_MESSAGE, MESSAGE_FIXED + size, cid,
                                                0, 0, 0), b""]
            names += [f"s{i}", f"t{i}", f"p{i}"]
            offsets += [pos + 11, pos + 15, pos + 23]  # sequence, log and publish time
            pos += MESSAGE_HEAD.size + size
        #: the sequence and times of a cycle's heads, in its records' bytes
        self.patch = np.dtype({"names": names, "formats": ["<u4", "<u8", "<u8"] * self.m,
                               "offsets": offsets, "itemsize": pos})
        self._fixed = True  # every cycle's data sizes are the first's (known at arrays)

    def sequences(self, counts: dict[int, int]) -> NDArray[np.int64] | None:
        """:func:`sequences` of the held cycles when each channel is once in a cycle
        (the k-th cycle's: its channels' counts plus k), else ``None``."""
        if not self.unique:
            return None
        k = len(self.times)
        base = np.array([counts.get(cid, 0) for cid in self.key], dtype=np.int64)
        for cid in self.key:
            counts[cid] = counts.get(cid, 0) + k
        return (base + np.arange(k, dtype=np.int64)[:, None]).reshape(-1)

    def arrays(self) -> tuple[NDArray[Any], NDArray[Any], NDArray[Any], NDArray[Any]]:
        k, m = len(self.times), self.m
        lens = list(map(len, self.datas))
        self._fixed = lens == self.lens * k
        sizes = np.tile(self.sizes, k) if self._fixed else np.array(lens, dtype=np.int64)
        return (np.tile(self.cids, k), np.repeat(np.array(self.times, dtype=np.uint64), m),
                sizes, np.full(k, m, dtype=np.int64))

    def records(self, c: NDArray[Any], t: NDArray[Any], sizes: NDArray[Any],
                seq: NDArray[Any]) -> bytearray:
        if not self._fixed:  # a message's size changed: one by one
            return _records(_heads(c, t, sizes, seq), self.datas)
        k = len(self.times)
        # a cycle's records from its template (heads with sequence 0 and time 0 between
        # placeholders for the data), repeated, the data put in, joined in one go; then
        # each head's sequence and times set through a numpy view of the bytes
        parts = self.template * k
        parts[1::2] = self.datas
        out = bytearray().join(parts)
        view = np.frombuffer(out, dtype=self.patch)
        seq = seq.reshape(k, self.m)
        for i in range(self.m):
            view[f"s{i}"] = seq[:, i]
        times = t[::self.m]
        for i in range(self.m):
            view[f"t{i}"] = times
            view[f"p{i}"] = times
        return out


@dataclass
class Framed:
    """Held messages framed, in order: their channels, log times, record sizes, and
    the records themselves, one after the other."""

    channels: NDArray[np.uint16]
    times: NDArray[np.uint64]
    sizes: NDArray[np.int64]
    records: memoryview


class Held:
    """Messages held in order (units of blocks), framed at once by :meth:`frame`."""

    def __init__(self) -> None:
        self._reset()

    def _reset(self) -> None:
        self._cycles: dict[tuple[int, ...], _Cycles] = {}
        self._blocks: list[_Cycles | _Loose | _Rows] = []
        self._last: _Cycles | None = None  # the block of the last cycle
        self._loose: _Loose | None = None
        self._rows: dict[tuple[int, int], _Rows] = {}
        self.units: list[int] = []  # per unit (call), its block's index in _blocks
        self.count = 0  # messages held
        self.size = 0  # their records' bytes (a cycle's: as its block's first)

    def cycle(self, cids: Sequence[int], log_time: int, datas: Sequence[bytes]) -> None:
        """A cycle's messages at one log time, of the channels ``cids`` (a sequence that
        must not change afterwards: a run's cycles give the same object)."""
        blk = self._last
        if blk is None or blk.key is not cids:
            if not cids:
                return
            blk = self._cycle_block(cids, datas)
        blk.times.append(log_time)
        blk.datas += datas
        self.units.append(blk.index)
        self.count += blk.m
        self.size += blk.size

    def _cycle_block(self, cids: Sequence[int], datas: Sequence[bytes]) -> _Cycles:
        key = tuple(cids)
        blk = self._cycles.get(key)
        if blk is None:
            blk = self._cycles[key] = _Cycles(len(self._blocks), cids, datas)
            self._blocks.append(blk)
        blk.key = cids
        self._last = blk
        return blk

    def loose(self, cids: Sequence[int], times: Sequence[int], datas: Sequence[bytes],
              size: int) -> None:
        """Messages of any channels at their own times (their records' ``size``), one
        unit (none when empty)."""
        if not cids:
            return
        blk = self._loose
        if blk is None:
            blk = self._loose = _Loose(len(self._blocks))
            self._blocks.append(blk)
        blk.cids += cids
        blk.times += times
        blk.datas += datas
        blk.counts.append(len(cids))
        self.units.append(blk.index)
        self.count += len(cids)
        self.size += size

    def rows(self, channel_id: int, times: Sequence[int], template: NDArray[Any],
             columns: Mapping[str, NDArray[Any]]) -> None:
        """Messages of one channel whose data are rows of ``template`` (one record) with
        ``columns`` assigned (the same fields every call; arrays that do not change
        afterwards), encoded at :meth:`frame` for all held at once."""
        k = len(times)
        if not k:
            return
        key = (channel_id, id(template))
        blk = self._rows.get(key)
        if blk is None or blk.template is not template:
            blk = self._rows[key] = _Rows(len(self._blocks), channel_id, template)
            self._blocks.append(blk)
        blk.times += times
        blk.counts.append(k)
        blk.columns.append(columns)
        self.units.append(blk.index)
        self.count += k
        self.size += k * (template.dtype.itemsize + MESSAGE_HEAD.size)

    def frame(self, counts: dict[int, int]) -> Framed:
        """Every held message framed, in the order given (each channel's sequence numbers
        counting on from ``counts``, updated); then nothing is held."""
        blocks, units = self._blocks, self.units
        self._reset()
        if len(blocks) == 1:  # one kind of unit: in its block's order
            blk = blocks[0]
            c, t, sizes, _ = blk.arrays()
            seq = None if isinstance(blk, _Loose) else blk.sequences(counts)
            if seq is None:
                seq = sequences(c, counts)
            return Framed(c, t, sizes, memoryview(blk.records(c, t, sizes, seq)))
        unit_block = np.array(units, dtype=np.int64)
        parts = [b.arrays() for b in blocks]
        where = [np.flatnonzero(unit_block == b) for b in range(len(blocks))]
        per_unit = np.empty(len(units), dtype=np.int64)  # messages per unit
        for w, p in zip(where, parts, strict=True):
            per_unit[w] = p[3]
        unit_start = np.cumsum(per_unit) - per_unit
        n = int(per_unit.sum())
        c = np.empty(n, dtype=np.uint16)
        t = np.empty(n, dtype=np.uint64)
        sizes = np.empty(n, dtype=np.int64)
        positions = []  # per block, where its messages go
        for w, (bc, bt, bs, bu) in zip(where, parts, strict=True):
            first = np.cumsum(bu) - bu  # each unit's first message in the block
            pos = np.repeat(unit_start[w] - first, bu) + np.arange(len(bc))
            c[pos], t[pos], sizes[pos] = bc, bt, bs
            positions.append(pos)
        seq = sequences(c, counts)
        records = [memoryview(b.records(p[0], p[1], p[2], seq[pos])).cast("B")
                   for b, p, pos in zip(blocks, parts, positions, strict=True)]
        # the units in order: each a run of its block's records
        ends = np.concatenate(([0], np.cumsum(sizes + MESSAGE_HEAD.size)))
        unit_bytes = ends[unit_start + per_unit] - ends[unit_start]
        starts = np.empty(len(units), dtype=np.int64)  # where each starts in its block's
        for w in where:
            b_bytes = unit_bytes[w]
            starts[w] = np.cumsum(b_bytes) - b_bytes
        runs = np.flatnonzero(np.diff(unit_block)) + 1  # runs of one block's units
        first = np.concatenate(([0], runs))
        last = np.append(runs - 1, len(units) - 1)
        out = [records[b][lo:hi] for b, lo, hi in zip(
            unit_block[first].tolist(), starts[first].tolist(),
            (starts[last] + unit_bytes[last]).tolist(), strict=True)]
        return Framed(c, t, sizes, memoryview(b"".join(out)))
