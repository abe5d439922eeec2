"""``load`` reads chunks itself: the same recording as through mcap's ``iter_messages``.

Every comparison is against :func:`load_with_mcap` (mcap's reader, a ``Message``
object per message) and, for the real runs, also against a decoding written here
from mcap's messages: arrays byte for byte with their dtypes, times, JSON messages,
metadata, attachments, warnings.
"""

from __future__ import annotations

import json
import struct
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, IndexType, Writer

from ffexp.errors import InputError
from ffexp.recording import Recording, load
from ffexp.recording.chunks import _index_records, _indexed, _walk, read_messages
from ffexp.recording.columns import json_messages
from ffexp.recording.reader import load_with_mcap
from ffexp.recording.topics import CDR_TOPICS

ROOT = Path(__file__).resolve().parent.parent
PROTOCOLS = ("method1_case1", "method2", "sixdof_method1")


def assert_same(a: Recording, b: Recording) -> None:
    """Two loads of one file are equal: the same topics in the same order, each array
    of the same dtype, shape and bytes."""
    assert list(a.topics) == list(b.topics)
    for name, x in a.topics.items():
        y = b.topics[name]
        assert x.log_time_ns.dtype == y.log_time_ns.dtype == np.int64
        assert np.array_equal(x.log_time_ns, y.log_time_ns), name
        assert list(x.fields) == list(y.fields), name
        for field, u in x.fields.items():
            v = y.fields[field]
            assert (u.dtype, u.shape) == (v.dtype, v.shape), (name, field)
            assert u.tobytes() == v.tobytes(), (name, field)
            assert (u.flags.c_contiguous, u.flags.writeable, u.base is None) == (
                v.flags.c_contiguous, v.flags.writeable, v.base is None), (name, field)
    assert list(a.json) == list(b.json)
    for name, j in a.json.items():
        assert np.array_equal(j.log_time_ns, b.json[name].log_time_ns), name
        assert j.messages == b.json[name].messages, name
    assert a.metadata == b.metadata
    assert a.attachments == b.attachments
    assert (a.complete, a.warnings) == (b.complete, b.warnings)


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    from ffexp.experiment import run_file

    out = tmp_path_factory.mktemp("runs")
    return {name: run_file(ROOT / "protocols" / f"{name}.toml", ["run.timeout_s=1.0"],
                           out_dir=out).path for name in PROTOCOLS}


def through_mcap(path: Path) -> tuple[dict[str, tuple[np.ndarray, list[bytes]]], dict[str, str]]:
    """Per topic, the log times and payloads mcap's reader gives, in log-time order (a
    stable sort of file order), and each topic's encoding."""
    by: dict[str, list[tuple[int, bytes]]] = {}
    encoding: dict[str, str] = {}
    with path.open("rb") as fh:
        reader = make_reader(fh)
        for channel in reader.get_summary().channels.values():  # type: ignore[union-attr]
            by[channel.topic] = []
            encoding[channel.topic] = channel.message_encoding
        for _s, channel, m in reader.iter_messages(log_time_order=False):
            by[channel.topic].append((m.log_time, m.data))
    out = {}
    for topic, msgs in by.items():
        msgs.sort(key=lambda tm: tm[0])  # list.sort is stable
        out[topic] = (np.array([t for t, _ in msgs], dtype=np.int64), [d for _, d in msgs])
    return out, encoding


@pytest.mark.parametrize("name", PROTOCOLS)
def test_a_run_loads_as_mcap_reads_it(runs: dict[str, Path], name: str) -> None:
    path = runs[name]
    rec = load(path)
    assert rec.complete and not rec.warnings
    assert_same(rec, load_with_mcap(path))
    messages, encoding = through_mcap(path)
    specs = {t.spec.name: t.spec for t in CDR_TOPICS.values()}
    for topic, (times, payloads) in messages.items():
        if encoding[topic] == "json":
            assert np.array_equal(rec.json[topic].log_time_ns, times)
            assert rec.json[topic].messages == [json.loads(p) for p in payloads]
            continue
        data = rec.topics[topic]
        assert np.array_equal(data.log_time_ns, times)
        spec = next(s for s in specs.values() if s.dtype.itemsize == len(payloads[0])
                    and set(data.fields) == {f.name for f in s.fields})
        for k in (0, len(payloads) // 2, len(payloads) - 1):  # the struct layout, a row
            values = spec.layout.unpack(payloads[k])[1:]
            flat = [v for f in spec.fields for v in np.atleast_1d(data[f.name][k]).tolist()]
            assert flat == list(values), (topic, k)


@pytest.mark.parametrize("name", PROTOCOLS)
def test_topic_and_time_selection_as_mcap(runs: dict[str, Path], name: str) -> None:
    path = runs[name]
    full = load(path)
    t0 = full.run_start_ns
    state = full.topics["/robot/state"].log_time_ns
    edge = int(state[len(state) // 3])  # a message's own time: the bounds' sides
    sites = [t for t in full.topics if t.startswith("/sim/site/")]
    cases: list[dict[str, Any]] = [
        {"topics": ["/ft/raw"]},
        {"topics": ["/tf", "/robot/state", "/no/such/topic"]},
        {"topics": sites},
        {"start_ns": edge},
        {"end_ns": edge},
        {"start_ns": edge, "end_ns": int(state[2 * len(state) // 3])},
        {"topics": ["/estimator/state", *sites], "start_ns": t0 + 300_000_000},
        {"start_ns": edge, "end_ns": edge},
        {"start_ns": int(state[-1]) + 1},
    ]
    for kw in cases:
        got = load(path, **kw)
        assert_same(got, load_with_mcap(path, **kw))
    window = load(path, start_ns=edge, end_ns=edge + 1)
    assert window.topics["/robot/state"].log_time_ns.tolist() == [edge]
    assert set(load(path, ["/ft/raw"]).topics) == {"/ft/raw"}
    assert sites and all(t in load(path, sites).topics for t in sites)


def test_the_index_finds_the_records_a_walk_finds(runs: dict[str, Path]) -> None:
    path = runs["method1_case1"]
    with path.open("rb") as fh:
        summary = make_reader(fh).get_summary()
        assert summary is not None and summary.chunk_indexes
        for ci in summary.chunk_indexes:
            fh.seek(ci.chunk_start_offset + 9)
            from mcap.data_stream import ReadDataStream
            from mcap.records import Chunk
            from mcap.stream_reader import get_chunk_data_stream

            stream, size = get_chunk_data_stream(Chunk.read(ReadDataStream(fh)), True)
            data = stream.read(size)
            found = _indexed(data, _index_records(fh, ci), ci)
            assert found is not None
            walked = _walk(data, 0, len(data))
            assert found.tolist() == walked
            assert all(data[at] == 0x05 for at in walked)  # message records' opcode


TOPIC = "/ft/raw"
SPEC = CDR_TOPICS[TOPIC].spec


def write_file(path: Path, times: list[int], *,
               compression: CompressionType = CompressionType.ZSTD,
               index_types: IndexType = IndexType.ALL, chunk_size: int = 600,
               chunked: bool = True) -> None:
    """A file of /ft/raw records at ``times`` (in that order), a JSON topic beside it,
    a topic of a nested schema and one of an unknown encoding, metadata and an
    attachment; small chunks."""
    rng = np.random.default_rng(len(times))
    with path.open("wb") as fh:
        w = Writer(fh, chunk_size=chunk_size, compression=compression, index_types=index_types,
                   use_chunking=chunked)
        w.start()
        ft = w.register_channel(TOPIC, "cdr", w.register_schema(
            SPEC.name, "ros2msg", SPEC.ros2msg.encode()))
        js = w.register_channel("/events", "json", w.register_schema("E", "jsonschema", b"{}"))
        nested = w.register_channel("/nested", "cdr", w.register_schema(
            "x/msg/N", "ros2msg", b"float64 a\n=====\nMSG: x/msg/B\nfloat64 b\n"))
        other = w.register_channel("/proto", "protobuf", 0)
        for k, t in enumerate(times):
            rec = SPEC.new_record()
            for f in SPEC.fields:
                rec[f.name] = rng.normal(size=rec[f.name].shape) * 100
            w.add_message(ft, t, rec.tobytes(), t, sequence=k)
            if k % 3 == 0:
                w.add_message(js, t, json.dumps({"k": k, "text": "é" * (k % 2)}).encode(), t)
            if k % 5 == 0:
                w.add_message(nested, t, b"\0" * 12, t)
                w.add_message(other, t, b"\x08\x01", t)
        w.add_metadata("setup", {"protocol": "p", "seed": "3"})
        w.add_attachment(1, 2, "protocol.toml", "text/plain", b"name = 'p'\n")
        w.finish()


# times out of order, with ties across chunks: each topic's stable sort by log time
TIMES = [50, 10, 30, 10, 20, 90, 30, 30, 5, 70, 60, 10, 45, 45, 80, 15, 30, 100, 25, 40] * 3


@pytest.mark.parametrize("compression", list(CompressionType))
@pytest.mark.parametrize(("index_types", "chunked"), [
    (IndexType.ALL, True), (IndexType.CHUNK, True),  # without message indexes
    (IndexType.NONE, True), (IndexType.ALL, False),  # no chunk index: mcap reads from the start
])
def test_any_compression_index_and_order(tmp_path: Path, compression: CompressionType,
                                         index_types: IndexType, chunked: bool) -> None:
    path = tmp_path / "x.mcap"
    write_file(path, TIMES, compression=compression, index_types=index_types, chunked=chunked)
    rec = load(path)
    assert_same(rec, load_with_mcap(path))
    assert rec.topics[TOPIC].log_time_ns.tolist() == sorted(TIMES)
    assert len(rec.warnings) == 2  # the nested schema and the unknown encoding
    for kw in ({"start_ns": 30, "end_ns": 70}, {"topics": ["/events"], "end_ns": 30},
               {"topics": [TOPIC], "start_ns": 45}):
        assert_same(load(path, **kw), load_with_mcap(path, **kw))


def patch_first_index_entry(path: Path, change: Callable[[int, int], tuple[int, int]]) -> None:
    """Rewrite the first entry (log time, offset) of the first message index in place."""
    with path.open("rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None
    ci = summary.chunk_indexes[0]
    at = min(ci.message_index_offsets.values()) + 1 + 8 + 2 + 4
    data = bytearray(path.read_bytes())
    t, off = struct.unpack_from("<QQ", data, at)
    struct.pack_into("<QQ", data, at, *change(t, off))
    path.write_bytes(bytes(data))


@pytest.mark.parametrize("change", [
    lambda t, off: (t + 1, off),  # a log time the record does not have
    lambda t, off: (t, off + 1),  # an offset that is not a record's
    lambda t, off: (t, 0),  # the offset of the chunk's first record, a schema
])
def test_an_index_that_lies_is_not_believed(tmp_path: Path,
                                            change: Callable[[int, int], tuple[int, int]]) -> None:
    path = tmp_path / "x.mcap"
    write_file(path, TIMES)
    patch_first_index_entry(path, change)
    assert_same(load(path), load_with_mcap(path))
    assert len(load(path).topics[TOPIC]) == len(TIMES)


def test_read_messages_by_channel_in_file_order(tmp_path: Path) -> None:
    path = tmp_path / "x.mcap"
    write_file(path, TIMES)
    with path.open("rb") as fh:
        summary = make_reader(fh).get_summary()
        assert summary is not None
        ids = {c.topic: cid for cid, c in summary.channels.items()}
        got = read_messages(fh, summary, {ids[TOPIC]}, start_ns=20, end_ns=80)
    assert set(got) == {ids[TOPIC]}
    kept = [t for t in TIMES if 20 <= t < 80]
    assert got[ids[TOPIC]].log_time_ns.tolist() == kept  # file order, not sorted
    assert got[ids[TOPIC]].sizes.tolist() == [SPEC.dtype.itemsize] * len(kept)
    rows = got[ids[TOPIC]].rows(SPEC.dtype.itemsize)
    assert [bytes(r) for r in rows] == got[ids[TOPIC]].payloads()
    assert all(p[:4] == b"\x00\x01\x00\x00" for p in got[ids[TOPIC]].payloads())


def test_a_corrupt_chunk_points_to_recover(runs: dict[str, Path], tmp_path: Path) -> None:
    with runs["method2"].open("rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None
    big = max(summary.chunk_indexes, key=lambda c: c.compressed_size)
    data = bytearray(runs["method2"].read_bytes())
    middle = big.chunk_start_offset + big.chunk_length // 2
    data[middle:middle + 16] = bytes(b ^ 0xFF for b in data[middle:middle + 16])
    bad = tmp_path / "corrupt.mcap"
    bad.write_bytes(bytes(data))
    for reader in (load, load_with_mcap):
        with pytest.raises(InputError, match=r"corrupt\.mcap: corrupt data .*ffexp recover"):
            reader(bad)


def test_a_truncated_tail_loads_through_recovery(runs: dict[str, Path], tmp_path: Path) -> None:
    data = runs["sixdof_method1"].read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 2 // 3])
    rec = load(cut)
    assert not rec.complete
    assert "recording is incomplete" in rec.warnings[0]
    assert 0 < len(rec.topics["/robot/state"]) < len(load(runs["sixdof_method1"]).topics[
        "/robot/state"])
    assert_same(rec, load_with_mcap(cut))
    assert_same(load(cut, ["/ft/raw"], start_ns=rec.run_start_ns + 100_000_000),
                load_with_mcap(cut, ["/ft/raw"], start_ns=rec.run_start_ns + 100_000_000))


def outcome(parse: Callable[[list[bytes]], list[Any]], payloads: list[bytes]) -> Any:
    try:
        return parse(payloads)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        return type(exc)


@pytest.mark.parametrize("payloads", [
    [b'{"a": 1}', b"[1, 2.5e3, null]", b'"x"', b"true", b"-0", b"NaN", b"Infinity"],
    [b"12", b"34"],  # a number that would run on into the next payload
    [b"1.", b"5"], [b"1", b"e5"], [b"nul", b"l"], [b"tru", b"e"],
    [b' \t{"a":[]}\n', b"\r\n 7 "],  # whitespace around a value
    [b"", b"1"], [b"  ", b"1"], [b"1", b""],  # no value
    [b'"a', b'b"'],  # a string split over two payloads
    [b'{"a":1},{"b":2}', b'{"c":[{}', b'{}]}'],  # brackets that balance only when joined
    [b'{"a": 1} x'], [b'{"a": 1}}'], [b'"tab\there"'],
    ['"é"'.encode(), b"1"], ['"é"'.encode("utf-16")], [b'\xef\xbb\xbf{"a": 1}'],
    [b'"\x00"'], [b"\xff"],
])
def test_json_messages_are_json_loads_of_each(payloads: list[bytes]) -> None:
    def each(ps: list[bytes]) -> list[Any]:
        return [json.loads(p) for p in ps]

    want, got = outcome(each, payloads), outcome(json_messages, payloads)
    if isinstance(want, list) and any(v != v for v in want):  # NaN: compare as text
        want, got = repr(want), repr(got)
    assert got == want
