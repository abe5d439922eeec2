"""The Recorder's faster mcap writer writes exactly the bytes mcap's own writer does
(its batches, and its chunks compressed in a worker thread while the next one fills)."""

from __future__ import annotations

import io

import numpy as np
from mcap.writer import CompressionType, Writer

from ffexp.recording.mcap_writer import FastWriter


def _write(cls: type[Writer], compression: CompressionType) -> tuple[bytes, Writer]:
    rng = np.random.default_rng(1)
    out = io.BytesIO()
    w = cls(out, chunk_size=4096, compression=compression)
    w.start(profile="ffexp", library="test")
    sid = w.register_schema("s", "ros2msg", b"float64 x\n")
    a = w.register_channel("/a", "cdr", sid)
    b = w.register_channel("/b", "json", w.register_schema("j", "jsonschema", b"{}"))
    w.add_metadata("run", {"k": "v"})
    for k in range(3000):  # many chunks; out of order now and then; empty and long payloads
        t = 10**9 + 1_000_000 * k - (700_000 if k % 17 == 0 else 0)
        size = int(rng.integers(0, 300))
        w.add_message(a if k % 3 else b, t, rng.bytes(size), t + 5, k % 70_000)
        if k == 1500:
            w.add_attachment(t, t, "a.toml", "application/toml", b"x = 1\n")
    w.finish()  # type: ignore[no-untyped-call]
    return out.getvalue(), w


def test_fast_writer_bytes_equal_mcaps_own() -> None:
    for compression in (CompressionType.ZSTD, CompressionType.NONE):
        ours, writer = _write(FastWriter, compression)
        theirs, _ = _write(Writer, compression)
        assert isinstance(writer, FastWriter) and writer.fast  # the fast path was taken
        # full zstd chunks compressed in the worker thread, written in order
        assert writer.background == (compression == CompressionType.ZSTD)
        assert len(ours) > 20_000
        assert ours == theirs


def _write_batches(cls: type[Writer]) -> bytes:
    """Messages in groups: ``FastWriter.add_messages`` (or ``add_messages_at``) for the
    group, mcap's own ``add_message`` one by one."""
    rng = np.random.default_rng(2)
    out = io.BytesIO()
    w = cls(out, chunk_size=2048, compression=CompressionType.ZSTD)
    w.start(profile="ffexp", library="test")
    sid = w.register_schema("s", "ros2msg", b"float64 x\n")
    channels = [w.register_channel(f"/c{k}", "cdr", sid) for k in range(4)]
    seq = [0] * 4
    for k in range(800):
        t = 10**9 + 5_000_000 * k - (3_000_000 if k % 13 == 0 else 0)
        group = [int(c) for c in rng.integers(0, 4, size=int(rng.integers(1, 9)))]
        datas = [rng.bytes(int(rng.integers(0, 400))) for _ in group]
        seqs = []
        for c in group:
            seqs.append(seq[c])
            seq[c] += 1
        cids = [channels[c] for c in group]
        # one log time for the group, or each its own (a sensor's samples), now and then
        # one before the chunk's earliest
        times = [t] * len(group) if k % 2 else [t - 200_000 * j for j in range(len(group))]
        if isinstance(w, FastWriter):
            if k % 4 == 1:  # a group at one time, as a cycle's topics
                w.add_messages_at(cids, t, datas, seqs)
            else:
                w.add_messages(cids, times, datas, seqs)
        else:
            for cid, ti, data, s in zip(cids, times, datas, seqs, strict=True):
                w.add_message(cid, ti, data, ti, s)
    w.finish()  # type: ignore[no-untyped-call]
    return out.getvalue()


def test_fast_writer_batches_bytes_equal_mcaps_own() -> None:
    ours = _write_batches(FastWriter)
    assert len(ours) > 50_000
    assert ours == _write_batches(Writer)


def _write_fixed(cls: type[Writer]) -> bytes:
    """Runs of same-sized messages of one channel (a cycle's F/T samples): ``FastWriter.
    add_fixed`` for the run, between single messages of another channel; mcap's own
    ``add_message`` one by one. Small chunks, so runs straddle a chunk's end."""
    rng = np.random.default_rng(3)
    dtype = np.dtype([("a", "<f8", (3,)), ("b", "<u4")])
    out = io.BytesIO()
    w = cls(out, chunk_size=1500, compression=CompressionType.ZSTD)
    w.start(profile="ffexp", library="test")
    sid = w.register_schema("s", "ros2msg", b"float64 x\n")
    fixed, other = (w.register_channel(t, "cdr", sid) for t in ("/f", "/o"))
    seq = 0
    for k in range(300):
        n = int(rng.integers(0, 9))
        times = 10**9 + 5_000_000 * k + 1_000_000 * np.arange(n, dtype=np.int64) - 4_000_000
        recs = np.zeros(n, dtype=dtype)
        recs["a"] = rng.normal(size=(n, 3))
        recs["b"] = rng.integers(0, 2**32, size=n)
        if isinstance(w, FastWriter):
            w.add_fixed(fixed, times, seq, recs)
        else:
            for i, t in enumerate(times.tolist()):
                w.add_message(fixed, t, recs[i].tobytes(), t, seq + i)
        seq += n
        t = 10**9 + 5_000_000 * k
        w.add_message(other, t, rng.bytes(int(rng.integers(0, 50))), t, k)
    w.finish()  # type: ignore[no-untyped-call]
    return out.getvalue()


def test_fast_writer_fixed_records_bytes_equal_mcaps_own() -> None:
    ours = _write_fixed(FastWriter)
    assert len(ours) > 20_000
    assert ours == _write_fixed(Writer)


def _write_held(cls: type[Writer]) -> bytes:
    """Cycles of messages: ``FastWriter.add_at`` (a cycle's topics, held and framed many
    cycles at once) and ``add_series`` (its samples), with ``reserve`` + ``add_fixed``,
    single messages, a channel registered and a flush on the way; mcap's own
    ``add_message`` one by one, each channel's sequence counting from 0."""
    rng = np.random.default_rng(4)
    out = io.BytesIO()
    w = cls(out, chunk_size=3000, compression=CompressionType.ZSTD)
    w.start(profile="ffexp", library="test")
    sid = w.register_schema("s", "ros2msg", b"float64 x\n")
    channels = [w.register_channel(f"/c{k}", "cdr", sid) for k in range(5)]
    seq: dict[int, int] = {}

    def own(cid: int, t: int, data: bytes) -> None:  # mcap's writer, sequences counted here
        s = seq.get(cid, 0)
        seq[cid] = s + 1
        w.add_message(cid, t, data, t, s)

    dtype = np.dtype([("a", "<f8", (2,)), ("b", "<u4")])
    for k in range(700):
        t = 10**9 + 5_000_000 * k
        n = int(rng.integers(0, 6))  # a cycle's samples, each at its own time, before it
        times = [t - 4_000_000 + 1_000_000 * j for j in range(n)]
        samples = [rng.bytes(20) for _ in range(n)]
        group = [channels[int(c)] for c in rng.integers(0, 4, size=int(rng.integers(1, 7)))]
        datas = [rng.bytes(int(rng.integers(0, 300))) for _ in group]
        if isinstance(w, FastWriter):
            w.add_series(channels[4], times, samples)
            w.add_at(group, t, datas)
        else:
            for ti, data in zip(times, samples, strict=True):
                own(channels[4], ti, data)
            for cid, data in zip(group, datas, strict=True):
                own(cid, t, data)
        if k % 50 == 7:  # records of a channel framed otherwise, between held messages
            recs = np.zeros(3, dtype=dtype)
            recs["a"] = rng.normal(size=(3, 2))
            rt = np.array([t + 1, t + 2, t + 3], dtype=np.int64)
            if isinstance(w, FastWriter):
                w.add_fixed(channels[0], rt, w.reserve(channels[0], 3), recs)
            else:
                for i in range(3):
                    own(channels[0], int(rt[i]), recs[i].tobytes())
        if k == 300:  # a new channel, and a flush, while messages are held
            channels.append(w.register_channel("/late", "json", sid))
            w.flush()  # type: ignore[no-untyped-call]
        if k > 300 and k % 3 == 0:
            if isinstance(w, FastWriter):
                w.add_at([channels[5]], t, [b"{}"])
            else:
                own(channels[5], t, b"{}")
    w.finish()  # type: ignore[no-untyped-call]
    return out.getvalue()


def test_time_batched_framing_bytes_equal_mcaps_own() -> None:
    """Held messages framed many cycles at once write the very file mcap's own writer
    does message by message: the same records, sequence numbers, chunks and indexes."""
    ours = _write_held(FastWriter)
    assert len(ours) > 50_000
    assert ours == _write_held(Writer)


def _write_cycles(cls: type[Writer], chunk_size: int) -> bytes:
    """Cycles of a few fixed topic tuples (one with a channel twice; now and then a
    message of another size, an empty one, a JSON-like one), framed from their templates
    by ``FastWriter.add_cycle``, interleaved with samples (``add_series``), rows
    (``add_rows``), single messages (``add_at``), records framed otherwise (``reserve``
    + ``add_fixed``), a channel registered and a flush on the way; mcap's own
    ``add_message`` one by one, each channel's sequence counting from 0."""
    rng = np.random.default_rng(6)
    out = io.BytesIO()
    w = cls(out, chunk_size=chunk_size, compression=CompressionType.ZSTD)
    w.start(profile="ffexp", library="test")
    sid = w.register_schema("s", "ros2msg", b"float64 x\n")
    ch = [w.register_channel(f"/c{k}", "cdr", sid) for k in range(6)]
    shapes = [[ch[0], ch[1], ch[2]], [ch[0], ch[1], ch[2], ch[3], ch[3]], [ch[2], ch[0]]]
    sizes = [[300, 60, 200], [300, 60, 200, 40, 40], [200, 300]]
    seq: dict[int, int] = {}

    def own(cid: int, t: int, data: bytes) -> None:
        s = seq.get(cid, 0)
        seq[cid] = s + 1
        w.add_message(cid, t, data, t, s)

    row = np.zeros(1, dtype=[("a", "<f8", (2,)), ("b", "<u4")])
    for k in range(1500):
        t = 10**9 + 5_000_000 * k
        if k % 3 == 0:  # samples before the cycle, as rows of a record or as bytes
            n = int(rng.integers(1, 5))
            times = [t - 4_000_000 + 1_000_000 * j for j in range(n)]
            cols = {"a": rng.normal(size=(n, 2)), "b": rng.integers(0, 9, size=n)}
            if isinstance(w, FastWriter):
                if k % 2:
                    w.add_rows(ch[4], times, row, cols)
                else:
                    w.add_series(ch[4], times, [r.tobytes() for r in _rows(row, cols, n)])
            else:
                for ti, r in zip(times, _rows(row, cols, n), strict=True):
                    own(ch[4], ti, r.tobytes())
        shape = 0 if k < 400 else int(rng.integers(0, 3))
        cids = shapes[shape]
        lens = list(sizes[shape])
        if k % 97 == 5:
            lens[0] += 8  # another size this cycle
        if k % 101 == 7:
            lens[-1] = 0  # an empty message
        datas = [rng.bytes(n) for n in lens]
        if isinstance(w, FastWriter):
            w.add_cycle(cids, t, datas)
        else:
            for cid, data in zip(cids, datas, strict=True):
                own(cid, t, data)
        if k % 211 == 9:  # an event between cycles
            if isinstance(w, FastWriter):
                w.add_at([ch[5]], t, [b'{"e":1}'])
            else:
                own(ch[5], t, b'{"e":1}')
        if k % 300 == 11:  # records framed otherwise, between held cycles
            recs = np.zeros(2, dtype=row.dtype)
            rt = np.array([t + 1, t + 2], dtype=np.int64)
            if isinstance(w, FastWriter):
                w.add_fixed(ch[1], rt, w.reserve(ch[1], 2), recs)
            else:
                for i in range(2):
                    own(ch[1], int(rt[i]), recs[i].tobytes())
        if k == 700:  # a new channel, and a flush, while cycles are held
            ch.append(w.register_channel("/late", "json", sid))
            shapes[2] = [ch[2], ch[6]]
            w.flush()  # type: ignore[no-untyped-call]
    w.finish()  # type: ignore[no-untyped-call]
    return out.getvalue()


def _rows(template: np.ndarray, cols: dict[str, np.ndarray], n: int) -> np.ndarray:
    rec = np.repeat(template, n)
    for name, value in cols.items():
        rec[name] = value
    return rec


def test_cycles_framed_from_a_template_bytes_equal_mcaps_own() -> None:
    """``add_cycle`` (a cycle's topics: the cycles of one topic tuple framed at once from
    one template, sequences and times patched) writes the very file mcap's own writer
    does message by message, with small chunks (cycles straddle a chunk's end) and with
    large ones (many cycles held, several tuples interleaved)."""
    for chunk_size in (2500, 1 << 20):
        ours = _write_cycles(FastWriter, chunk_size)
        assert len(ours) > 400_000
        assert ours == _write_cycles(Writer, chunk_size)
