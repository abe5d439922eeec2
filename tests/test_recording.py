"""Recorder and reader: CDR layout, round trips, selection, crash safety, bad files."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from mcap.writer import Writer

from ffexp.errors import InputError
from ffexp.recording import Recorder, load, recover
from ffexp.recording.schema import CDR_HEADER, FieldSpec, MessageSpec
from ffexp.recording.topics import CDR_TOPICS, JSON_TOPICS, describe


def test_cdr_alignment_counts_from_after_the_header() -> None:
    spec = MessageSpec(
        "t/msg/A",
        (
            FieldSpec("flag", "uint8"),
            FieldSpec("x", "float64", 2),
            FieldSpec("n", "uint16"),
            FieldSpec("k", "int32"),
        ),
    )
    dt = spec.dtype
    # header 4 bytes; flag at 0 (+4); x aligned to 8 -> 8 (+4); n at 24 (+4); k aligned to 4 -> 28
    assert [dt.fields[n][1] for n in ("flag", "x", "n", "k")] == [4, 12, 28, 32]
    assert dt.itemsize == 36
    assert spec.ros2msg.splitlines() == ["uint8 flag", "float64[2] x", "uint16 n", "int32 k"]
    rec = spec.new_record()
    rec["x"] = [1.5, -2.0]
    rec["k"] = -7
    raw = rec.tobytes()
    assert raw[:4] == b"\x00\x01\x00\x00"
    assert np.frombuffer(raw[12:28], "<f8").tolist() == [1.5, -2.0]
    assert int.from_bytes(raw[32:36], "little", signed=True) == -7


def random_fill(rec: np.ndarray, rng: np.random.Generator) -> None:
    for name in rec.dtype.names or ():
        if name == "_cdr_header":
            continue
        field = rec[name]
        if field.dtype.kind == "f":
            rec[name] = rng.normal(size=field.shape)
        else:
            info = np.iinfo(field.dtype)
            rec[name] = rng.integers(info.min, info.max, size=field.shape, endpoint=True)


def write_all_topics(
    path: Path, n: int, seed: int = 0, chunk_size: int = 1 << 20
) -> dict[str, list[np.ndarray]]:
    rng = np.random.default_rng(seed)
    written: dict[str, list[np.ndarray]] = {t: [] for t in CDR_TOPICS}
    with Recorder(path, chunk_size=chunk_size) as rec:
        rec.metadata("run", {"protocol": "test", "seed": str(seed)})
        rec.attach("protocol.toml", b"name = 'x'\n", "application/toml", 0)
        for k in range(n):
            t_ns = 1_700_000_000_000_000_000 + k * 5_000_000
            for topic in CDR_TOPICS:
                r = rec.record(topic)
                random_fill(r, rng)
                rec.write(topic, t_ns)
                written[topic].append(r.copy())
            if k % 10 == 0:
                rec.log(t_ns, "INFO", "tick", f"cycle {k}")
                pose = np.eye(4)
                pose[:3, 3] = [k, 0, 0]
                rec.transform(t_ns, "base", "tool", pose)
        rec.write_json("/runner/phase", t_ns, {  # the run's end: a whole run's file
            "phase": "DONE", "phase_id": 3, "reason": "test", "stop_reason": "timeout",
            "aligned": False})
    return written


def test_round_trip_every_field_of_every_topic(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    written = write_all_topics(path, 50)
    loaded = load(path)
    assert loaded.complete and not loaded.warnings
    for topic, records in written.items():
        data = loaded.topic(topic)
        assert len(data) == 50
        for f in CDR_TOPICS[topic].spec.fields:
            expected = np.concatenate([r[f.name] for r in records])
            np.testing.assert_array_equal(data[f.name], expected)
        assert np.all(np.diff(data.log_time_ns) == 5_000_000)
    assert loaded.metadata["run"] == {"protocol": "test", "seed": "0"}
    assert loaded.attachments["protocol.toml"] == b"name = 'x'\n"
    events = loaded.json["/events"].messages
    assert [e["message"] for e in events] == [f"cycle {k}" for k in range(0, 50, 10)]
    tf = loaded.json["/tf"].messages[2]
    assert tf["translation"]["x"] == 20 and tf["rotation"]["w"] == pytest.approx(1.0)


def test_topic_and_time_selection(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    write_all_topics(path, 100)
    t0 = 1_700_000_000_000_000_000
    start, end = t0 + 10 * 5_000_000, t0 + 20 * 5_000_000
    part = load(path, topics=["/robot/link"], start_ns=start, end_ns=end)
    assert set(part.topics) == {"/robot/link"}
    assert part.topics["/robot/link"].log_time_ns.tolist() == [
        t0 + k * 5_000_000 for k in range(10, 20)
    ]


def test_flush_bounds_what_a_kill_loses(tmp_path: Path) -> None:
    """At any moment the bytes on disk hold everything written up to the last
    flush, and flushes come at least once a second of wall time."""
    now = [0.0]
    path = tmp_path / "run.mcap"
    rec = Recorder(path, clock=lambda: now[0], flush_interval_s=1.0)
    r = rec.record("/robot/link")
    for k in range(5000):  # 5 s of wall time, one message per ms
        now[0] = k * 1e-3
        r["miss_counter"] = k
        rec.write("/robot/link", k * 1_000_000)
        if k in (1500, 3999, 4999):
            snapshot = tmp_path / f"killed_{k}.mcap"
            shutil.copyfile(path, snapshot)  # what a kill -9 would leave behind
            got = load(snapshot)
            assert not got.complete and got.warnings
            counters = got.topics["/robot/link"]["miss_counter"]
            assert counters.tolist() == list(range(len(counters)))
            assert k - len(counters) <= 1000  # lost at most 1 s of data
    rec.finish()
    assert load(path).complete


def test_recover_rewrites_a_valid_indexed_file(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    written = write_all_topics(path, 400, chunk_size=64 * 1024)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[: path.stat().st_size * 2 // 3])
    partial = load(cut)
    n = len(partial.topics["/robot/measurement"])
    assert 0 < n < 400
    result = recover(cut, tmp_path / "fixed.mcap")
    assert not result.complete and result.messages > 0
    fixed = load(tmp_path / "fixed.mcap")
    # a valid file, but without the run's end (its DONE was in the part cut off)
    assert not fixed.complete
    assert [w.split(": ", 1)[1] for w in fixed.warnings] == [
        "the run's end is not recorded (no DONE or ABORT on /runner/phase): the run ended "
        "abnormally"]
    seqs = fixed.topics["/robot/measurement"]["seq"]
    expected = np.concatenate([r["seq"] for r in written["/robot/measurement"][: len(seqs)]])
    np.testing.assert_array_equal(seqs, expected)
    assert fixed.metadata["run"]["protocol"] == "test"


@pytest.mark.parametrize(
    ("content", "message"),
    [(b"", "empty file"), (b"hello, world\n" * 10, "not an MCAP file")],
)
def test_bad_files_give_one_clear_error(tmp_path: Path, content: bytes, message: str) -> None:
    path = tmp_path / "bad.mcap"
    path.write_bytes(content)
    with pytest.raises(InputError, match=message) as info:
        load(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)
    with pytest.raises(InputError, match="file not found"):
        load(tmp_path / "missing.mcap")


def test_foreign_mcap_loads_what_it_understands(tmp_path: Path) -> None:
    path = tmp_path / "foreign.mcap"
    with path.open("wb") as fh:
        w = Writer(fh)
        w.start()
        flat = w.register_schema("pkg/msg/Flat", "ros2msg", b"float64 a\nint32[2] b\n")
        nested = w.register_schema("pkg/msg/Nested", "ros2msg", b"pkg/Flat f\n" + b"=" * 80)
        proto = w.register_schema("pkg.Proto", "protobuf", b"\x00")
        c1 = w.register_channel("/flat", "cdr", flat)
        c2 = w.register_channel("/nested", "cdr", nested)
        c3 = w.register_channel("/proto", "protobuf", proto)
        body = np.float64(2.5).tobytes() + np.array([3, -4], "<i4").tobytes()
        payload = b"\x00\x01\x00\x00" + body
        for cid in (c1, c2, c3):
            w.add_message(cid, 7, payload, 7)
        w.finish()
    got = load(path)
    assert got.topics["/flat"]["a"].tolist() == [2.5]
    assert got.topics["/flat"]["b"].tolist() == [[3, -4]]
    assert {"/nested", "/proto"}.isdisjoint(got.topics)
    assert len(got.warnings) == 2


def test_topics_are_documented() -> None:
    text = describe()
    for topic in [*CDR_TOPICS, *JSON_TOPICS]:
        assert topic in text
    for t in CDR_TOPICS.values():
        for f in t.spec.fields:
            assert f" {f.name}" in text


def test_transform_quaternion_matches_scipy() -> None:
    from scipy.spatial.transform import Rotation

    from ffexp.recording.recorder import pose_to_transform

    for r in Rotation.random(300, random_state=1).as_matrix():
        pose = np.eye(4)
        pose[:3, :3] = r
        pose[:3, 3] = [1.0, -2.0, 0.5]
        t, q = pose_to_transform(pose)
        got = np.array([q["x"], q["y"], q["z"], q["w"]])
        ref = Rotation.from_matrix(r).as_quat()
        assert min(np.abs(got - ref).max(), np.abs(got + ref).max()) < 1e-9
        assert t == {"x": 1.0, "y": -2.0, "z": 0.5}


def test_write_fields_takes_any_shape_of_the_same_numbers(tmp_path: Path) -> None:
    """A 4x4 pose, then the same field as 16 flat numbers, then 4x4 again: all recorded."""
    from types import SimpleNamespace

    from drivers.fri.types import FriMeasurement

    path = tmp_path / "f.mcap"
    poses = [np.arange(16.0).reshape(4, 4) + k for k in range(3)]
    with Recorder(path) as rec:
        m = FriMeasurement()
        for k, pose in enumerate(poses):
            m.msr_cart_pos = pose if k != 1 else pose.reshape(-1)
            m.seq = k
            rec.write_fields("/robot/measurement", 1000 + k, m)
        other = SimpleNamespace(**{f.name: getattr(m, f.name)
                                   for f in CDR_TOPICS["/robot/measurement"].spec.fields})
        other.seq = 9
        rec.write_fields("/robot/measurement", 2000, other)  # another source type
    data = load(path).topic("/robot/measurement")
    np.testing.assert_array_equal(data["msr_cart_pos"][:3], [p.reshape(-1) for p in poses])
    assert data["seq"].tolist() == [0, 1, 2, 9]


def test_an_abort_loses_nothing_held(tmp_path: Path) -> None:
    """The recorder's writer holds a cycle's messages and frames many cycles at once;
    a run that ends in an exception still has every message it wrote, in order, each
    channel's sequence numbers counting from 0."""
    from mcap.reader import make_reader

    path = tmp_path / "run.mcap"
    rec = Recorder(path, clock=lambda: 0.0)  # no flush by time
    link = rec.layout("/robot/link")
    with pytest.raises(RuntimeError), rec:
        for k in range(300):
            t = 1_700_000_000_000_000_000 + 5_000_000 * k
            msgs = [("/robot/link", link.pack(CDR_HEADER, 0.5, 0.0, 0.0, 0.0, k, 2, 3))]
            if k % 4 == 0:
                msgs.append(("/tf", rec.encode_transform(t, "base", "tool", np.eye(4).tolist())))
            rec.write_batch(t, msgs)
        raise RuntimeError("abort")
    got = load(path)
    assert got.complete
    assert got.topics["/robot/link"]["miss_counter"].tolist() == list(range(300))
    with path.open("rb") as f:
        seen: dict[str, list[int]] = {}
        for _, ch, m in make_reader(f).iter_messages(log_time_order=False):
            seen.setdefault(ch.topic, []).append(m.sequence)
    assert seen == {"/robot/link": list(range(300)), "/tf": list(range(75))}


def test_rows_held_and_encoded_at_once_are_the_records_filled_row_by_row(
        tmp_path: Path) -> None:
    """``write_rows`` (a cycle's F/T samples, encoded with those of many cycles at
    once) writes each row as the topic's record filled with that row (numpy's casts:
    a sequence number beyond 32 bits wraps), in order among the cycle's other
    messages; with a tap, the same messages at once."""
    from mcap.reader import make_reader

    expected: list[tuple[str, int, bytes]] = []
    tapped: list[tuple[str, int, bytes]] = []
    proto = CDR_TOPICS["/ft/raw"].spec.new_record()
    paths = [tmp_path / "held.mcap", tmp_path / "tapped.mcap"]
    for path in paths:
        rng = np.random.default_rng(5)
        with Recorder(path, clock=lambda: 0.0, chunk_size=4096) as rec:
            if path.name == "tapped.mcap":
                rec.taps.append(lambda topic, t, data: tapped.append((topic, t, data)))
            link = rec.layout("/robot/link")
            seq = 2**32 - 7
            for k in range(400):
                t = 1_700_000_000_000_000_000 + 5_000_000 * k
                n = int(rng.integers(0, 6))
                times = [t - 4_000_000 + 1_000_000 * j for j in range(n)]
                wrench = rng.normal(size=(n, 6))
                seqs = np.arange(seq, seq + n, dtype=np.int64)
                seq += n
                status = rng.integers(0, 3, size=n).astype(np.uint32)
                rec.write_rows("/ft/raw", times, {"wrench": wrench, "seq": seqs,
                                                  "status": status})
                wrench[:] = 0.0  # written: the recording keeps the values given
                rec.write_batch(t, [("/robot/link", link.pack(CDR_HEADER, 0.5, 0.0, 0.0, 0.0,
                                                              k, 2, 3))])
                if k == 200:
                    rec.flush()
    with paths[0].open("rb") as f:
        held = [(ch.topic, m.log_time, m.data)
                for _, ch, m in make_reader(f).iter_messages(log_time_order=False)]
    with paths[1].open("rb") as f:
        direct = [(ch.topic, m.log_time, m.data)
                  for _, ch, m in make_reader(f).iter_messages(log_time_order=False)]
    assert held == direct == tapped
    # each /ft/raw message is the record of its row
    rng = np.random.default_rng(5)
    seq = 2**32 - 7
    for k in range(400):
        n = int(rng.integers(0, 6))
        wrench = rng.normal(size=(n, 6))
        status = rng.integers(0, 3, size=n).astype(np.uint32)
        for j in range(n):
            r = proto.copy()
            r["wrench"] = wrench[j]
            r["seq"] = (seq + j) & 0xFFFFFFFF
            r["status"] = status[j]
            expected.append(("/ft/raw", 1_700_000_000_000_000_000 + 5_000_000 * k
                             - 4_000_000 + 1_000_000 * j, r.tobytes()))
        seq += n
    assert [m for m in held if m[0] == "/ft/raw"] == expected
    assert len(expected) > 500


def test_a_cycles_topics_given_as_the_last_tuple_again_go_to_their_channels(
        tmp_path: Path) -> None:
    """``write_cycle`` knows the channels of the tuple of topics it was given last (the
    same object); another tuple, a list or new topics in between go where they belong:
    the file is the one of writing every message by itself."""
    a = ("/estimator/state", "/control/terms")
    b = ("/control/terms", "/sim/truth", "/estimator/state")
    rng = np.random.default_rng(3)
    sizes = {t: CDR_TOPICS[t].spec.new_record().nbytes for t in (*a, *b)}
    cycles = []
    for k in range(300):
        topics: tuple[str, ...] | list[str] = a if k % 7 else b
        if k % 11 == 3:
            topics = list(topics)  # a list: asked every time
        if k % 13 == 5:
            topics = tuple(list(a))  # a tuple of the same topics, another object
        cycles.append((10**9 + 1000 * k, topics,
                       [rng.bytes(sizes[t]) for t in topics]))
    with Recorder(tmp_path / "cycles.mcap") as rec:
        for t, topics, datas in cycles:
            rec.write_cycle(t, topics, datas)
    with Recorder(tmp_path / "each.mcap") as rec:
        for t, topics, datas in cycles:
            for topic, data in zip(topics, datas, strict=True):
                rec.write_bytes(topic, t, data)
    want, got = _messages(tmp_path / "each.mcap"), _messages(tmp_path / "cycles.mcap")
    assert got == want
    assert len(got["/sim/truth"]) == sum(1 for _, tp, _ in cycles if "/sim/truth" in tp)
    with Recorder(tmp_path / "bad.mcap") as rec, pytest.raises(ValueError, match="2 topics"):
        rec.write_cycle(1, a, [b"x"] * 2)
        rec.write_cycle(2, a, [b"x"] * 3)  # the last tuple, with a message too many


def _messages(path: Path) -> dict[str, list[tuple[int, int, bytes]]]:
    from mcap.reader import make_reader

    out: dict[str, list[tuple[int, int, bytes]]] = {}
    with path.open("rb") as fh:
        for _, ch, msg in make_reader(fh).iter_messages():
            out.setdefault(ch.topic, []).append((msg.sequence, msg.log_time, msg.data))
    return out
