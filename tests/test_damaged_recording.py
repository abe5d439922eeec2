"""A damaged recording is bad input: one ``error:`` line naming the file and the chunk,
exit 2, never a library's error or a traceback; what a command could read is kept.

The damage is made at known byte offsets of a real run's recording, rewritten with
each compression mcap knows (zstd as ffexp writes it, lz4 as another writer may, none)
in small chunks: a chunk's compressed data whose frame header or tail is broken (lz4's
errors are plain ``RuntimeError``), a CRC that does not match, an unknown compression,
and, in a chunk without a CRC, records whose lengths run past the chunk's end.
"""

from __future__ import annotations

import pickle
import struct
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.records import ChunkIndex
from mcap.writer import CompressionType, Writer
from typer.testing import CliRunner

from ffexp.cli import app
from ffexp.errors import CorruptRecordingError, InputError
from ffexp.recording import load
from ffexp.recording.chunks import decompression_failed
from ffexp.recording.reader import contents, load_with_mcap, recover

ROOT = Path(__file__).resolve().parents[1]
runner = CliRunner()


@pytest.fixture(scope="module")
def run_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from ffexp.experiment import run_file

    out = tmp_path_factory.mktemp("run")
    return run_file(ROOT / "protocols" / "method2.toml", ["run.timeout_s=0.5"],
                    out_dir=out).path


def rewrite(src: Path, dst: Path, compression: CompressionType) -> None:
    """``src`` with every record as it is, in 32 KiB chunks of ``compression``."""
    with src.open("rb") as fh, dst.open("wb") as out:
        reader = make_reader(fh)
        summary = reader.get_summary()
        assert summary is not None
        w = Writer(out, compression=compression, chunk_size=32 * 1024)
        w.start(profile="ffexp", library="test")
        schemas = {k: w.register_schema(s.name, s.encoding, s.data)
                   for k, s in summary.schemas.items()}
        channels = {k: w.register_channel(c.topic, c.message_encoding,
                                          schemas.get(c.schema_id, 0), dict(c.metadata))
                    for k, c in summary.channels.items()}
        for _s, c, m in reader.iter_messages(log_time_order=False):
            w.add_message(channels[c.id], m.log_time, m.data, m.publish_time, m.sequence)
        for md in reader.iter_metadata():
            w.add_metadata(md.name, dict(md.metadata))
        for a in reader.iter_attachments():
            w.add_attachment(a.create_time, a.log_time, a.name, a.media_type, a.data)
        w.finish()


def chunk_indexes(path: Path) -> list[ChunkIndex]:
    with path.open("rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None
    return list(summary.chunk_indexes)


class ChunkAt:
    """Byte offsets of one chunk record's fields (the MCAP spec's Chunk record)."""

    def __init__(self, data: bytes | bytearray, ci: ChunkIndex) -> None:
        at = ci.chunk_start_offset + 1 + 8  # opcode, record length
        self.crc = at + 8 + 8 + 8  # after start time, end time, uncompressed size
        (n,) = struct.unpack_from("<I", data, self.crc + 4)
        self.compression = self.crc + 4 + 4  # its string's bytes
        self.records = self.compression + n + 8  # after the records' byte length
        (self.length,) = struct.unpack_from("<Q", data, self.compression + n)


def damage(src: Path, dst: Path, number: int,
           change: Callable[[bytearray, ChunkAt], None]) -> tuple[Path, int]:
    """``src`` with chunk ``number`` (from 1) changed; the chunk's byte offset."""
    ci = chunk_indexes(src)[number - 1]
    data = bytearray(src.read_bytes())
    change(data, ChunkAt(data, ci))
    dst.write_bytes(bytes(data))
    return dst, ci.chunk_start_offset


def flip(at: int, n: int = 4) -> Callable[[bytearray, ChunkAt], None]:
    def change(data: bytearray, c: ChunkAt) -> None:
        start = c.records + at if at >= 0 else c.records + c.length + at
        data[start:start + n] = bytes(b ^ 0xFF for b in data[start:start + n])
    return change


def zero_tail(data: bytearray, c: ChunkAt) -> None:
    end = c.records + c.length
    data[end - 24:end] = bytes(24)


def bad_crc(data: bytearray, c: ChunkAt) -> None:
    struct.pack_into("<I", data, c.crc, struct.unpack_from("<I", data, c.crc)[0] ^ 1)


def unknown_compression(data: bytearray, c: ChunkAt) -> None:
    data[c.compression:c.compression + 4] = b"zstx"


def no_crc_and(edit: Callable[[bytearray, int, list[int]], None]
               ) -> Callable[[bytearray, ChunkAt], None]:
    """The chunk's CRC set to 0 (not checked, as the spec allows), then ``edit`` of its
    records (uncompressed) given the records' start and each record's offset."""
    def change(data: bytearray, c: ChunkAt) -> None:
        struct.pack_into("<I", data, c.crc, 0)
        heads, pos = [], c.records
        while pos < c.records + c.length:
            heads.append(pos)
            pos += 9 + struct.unpack_from("<Q", data, pos + 1)[0]
        edit(data, c.records, heads)
    return change


def overrun_last(data: bytearray, start: int, heads: list[int]) -> None:
    length = struct.unpack_from("<Q", data, heads[-1] + 1)[0]
    struct.pack_into("<Q", data, heads[-1] + 1, length + 100)


def overrun_first(data: bytearray, start: int, heads: list[int]) -> None:
    struct.pack_into("<Q", data, heads[0] + 1, 1 << 40)


def overrun_huge(data: bytearray, start: int, heads: list[int]) -> None:
    struct.pack_into("<Q", data, heads[1] + 1, 2**64 - 1)  # past any buffer: OverflowError


def short_message(data: bytearray, start: int, heads: list[int]) -> None:
    """The last message record cut to 3 bytes, the rest of it a record of an opcode no
    reader knows (the records still tile the chunk)."""
    last = max(h for h in heads if data[h] == 0x05)  # a message record
    length = struct.unpack_from("<Q", data, last + 1)[0]
    struct.pack_into("<Q", data, last + 1, 3)
    struct.pack_into("<BQ", data, last + 9 + 3, 0x80, length - 3 - 9)


#: (name, compression, chunk, change, the reason the error line gives)
DAMAGE = [
    ("lz4_header", CompressionType.LZ4, 2, flip(0), "its lz4 data does not decompress"),
    ("lz4_flags", CompressionType.LZ4, 1, flip(4, 1), "its lz4 data does not decompress"),
    ("lz4_tail", CompressionType.LZ4, 2, zero_tail, "its lz4 data does not decompress"),
    ("zstd_header", CompressionType.ZSTD, 2, flip(0), "its zstd data does not decompress"),
    ("zstd_body", CompressionType.ZSTD, 1, flip(-12, 8), "chunk 1 at byte"),
    ("crc", CompressionType.NONE, 2, bad_crc, "its CRC does not match its data"),
    ("compression", CompressionType.ZSTD, 2, unknown_compression, "unknown compression 'zstx'"),
    ("overrun_last", CompressionType.NONE, 2, no_crc_and(overrun_last),
     "runs past the chunk's end"),
    ("overrun_first", CompressionType.NONE, 1, no_crc_and(overrun_first),
     "the record at byte 0 of its data runs past the chunk's end"),
    ("overrun_huge", CompressionType.NONE, 1, no_crc_and(overrun_huge),
     "runs past the chunk's end"),
    ("short_message", CompressionType.NONE, 2, no_crc_and(short_message),
     "shorter than its fields"),
]


@pytest.fixture(scope="module")
def damaged(run_path: Path, tmp_path_factory: pytest.TempPathFactory
            ) -> dict[str, tuple[Path, int, int, str]]:
    """By name: the damaged file, its damaged chunk's number and offset, the reason."""
    d = tmp_path_factory.mktemp("damaged")
    out = {}
    for compression in (CompressionType.LZ4, CompressionType.ZSTD, CompressionType.NONE):
        rewrite(run_path, d / f"good_{compression.value or 'none'}.mcap", compression)
    for name, compression, number, change, reason in DAMAGE:
        good = d / f"good_{compression.value or 'none'}.mcap"
        assert len(chunk_indexes(good)) >= 3
        path, offset = damage(good, d / f"{name}.mcap", number, change)
        out[name] = (path, number, offset, reason)
    return out


@pytest.mark.parametrize("name", [d[0] for d in DAMAGE])
def test_load_names_the_file_and_the_chunk(damaged: dict[str, tuple[Path, int, int, str]],
                                           name: str) -> None:
    path, number, offset, reason = damaged[name]
    with pytest.raises(CorruptRecordingError) as err:
        load(path)
    text = str(err.value)
    assert text.startswith(f"{path}: corrupt data (chunk {number} at byte {offset}: ")
    assert reason in text and f"`ffexp recover {path}`" in text
    assert "\n" not in text and err.value.exit_code == 2
    with pytest.raises(CorruptRecordingError, match="ffexp recover"):
        load(path, ["/robot/state"])  # the damaged chunk holds every topic
    if not name.startswith(("overrun", "short")):
        # mcap's own reader (it reads message records through the index only)
        with pytest.raises(InputError, match=f"{path.name}: corrupt data"):
            load_with_mcap(path)


@pytest.mark.parametrize("name", [d[0] for d in DAMAGE])
def test_topics_and_recover_read_around_the_damage(
        damaged: dict[str, tuple[Path, int, int, str]], tmp_path: Path, name: str) -> None:
    path, number, _offset, _reason = damaged[name]
    seen = contents(path)  # from the summary: every topic, with a warning at most
    assert {r["topic"] for r in seen.rows} >= {"/robot/state", "/runner/phase"}
    assert all("corrupt data" in w and f"chunk {number} at byte" in w for w in seen.warnings)
    result = recover(path, tmp_path / "r.mcap")
    if name.startswith(("overrun", "short")):
        return  # the reader of a stream skips what no record of it says is a message
    assert result.corrupt_chunks == (number,)
    rec = load(tmp_path / "r.mcap")
    assert not rec.complete and any(f"corrupt chunk(s) {number}" in w for w in rec.warnings)


def test_the_error_survives_a_process_pool() -> None:
    err = CorruptRecordingError("a.mcap", "chunk 2 at byte 9: its CRC does not match")
    back = pickle.loads(pickle.dumps(err))
    assert type(back) is CorruptRecordingError and str(back) == str(err)
    assert (back.path, back.reason) == (err.path, err.reason)


def test_only_a_decompressor_s_error_is_damage() -> None:
    import lz4.frame
    import zstandard

    with pytest.raises(RuntimeError) as lz4_err:
        lz4.frame.decompress(b"\x04\x22\x4d\x18" + bytes(12))
    with pytest.raises(RuntimeError) as cut:
        lz4.frame.decompress(lz4.frame.compress(b"x" * 1000)[:-5])
    with pytest.raises(zstandard.ZstdError) as zstd_err:
        zstandard.decompress(b"\x28\xb5\x2f\xfd" + bytes(12))
    assert all(decompression_failed(e.value) for e in (lz4_err, cut, zstd_err))
    assert not decompression_failed(RecursionError("LZ4F_ in a message"))
    assert not decompression_failed(RuntimeError("dictionary changed size during iteration"))


def check_one_line(code: int, stderr: str, needles: list[str]) -> None:
    assert "Traceback" not in stderr and "internal error" not in stderr, stderr
    lines = [x for x in stderr.splitlines() if x.strip() and not x.startswith("warning: ")]
    assert len(lines) == 1 and lines[0].startswith("error: "), stderr
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    assert code == 2, (code, stderr)


#: Every command that reads a recording, with the damaged one in {bad} and a good one in
#: {good}; {out} is a path that must not be left behind.
COMMANDS = [
    "analyze {bad}", "analyze {good} {bad}", "analyze --json {bad}", "compare {good} {bad}",
    "compare {bad} --csv {out}", "diff {good} {bad}", "diff {bad} {good}",
    "export {bad} --out {out}", "replay {bad} --out {out}.mcap",
    "resimulate {bad} --out {out}.mcap",
]


@pytest.mark.parametrize("name", ["lz4_header", "lz4_tail", "zstd_header", "crc",
                                  "overrun_last"])
@pytest.mark.parametrize("line", COMMANDS)
def test_every_command_says_one_line_and_exits_2(
        damaged: dict[str, tuple[Path, int, int, str]], run_path: Path, tmp_path: Path,
        line: str, name: str) -> None:
    path, number, offset, _reason = damaged[name]
    out = tmp_path / "out"
    args = [a.format(bad=path, good=run_path, out=out) for a in line.split()]
    result = runner.invoke(app, args)
    check_one_line(result.exit_code, result.stderr,
                   [str(path), f"chunk {number} at byte {offset}", "ffexp recover"])
    assert not out.exists() and not out.with_suffix(".mcap").exists()


def test_topics_lists_what_the_summary_holds(damaged: dict[str, tuple[Path, int, int, str]]
                                             ) -> None:
    path, _number, _offset, _reason = damaged["lz4_header"]
    first, _o, _off, _r = damaged["lz4_flags"]  # chunk 1: the attached frames are in it
    for p in (path, first):
        result = runner.invoke(app, ["topics", str(p)])
        assert result.exit_code == 0, result.stderr
        assert "/robot/state" in result.stdout and "Traceback" not in result.stderr
    assert "warning: " in runner.invoke(app, ["topics", str(first)]).stderr


def test_report_keeps_the_good_runs_and_names_the_damaged_one(
        damaged: dict[str, tuple[Path, int, int, str]], run_path: Path, tmp_path: Path
) -> None:
    import shutil

    d = tmp_path / "campaign"
    d.mkdir()
    shutil.copy(run_path, d / "good.mcap")
    bad, number, offset, _reason = damaged["lz4_header"]
    shutil.copy(bad, d / "bad.mcap")
    result = runner.invoke(app, ["report", str(d), "--out", str(tmp_path / "r.html")])
    assert result.exit_code == 0, result.stderr
    page = (tmp_path / "r.html").read_text()
    assert f"chunk {number} at byte {offset}" in page and "bad.mcap" in page
    assert run_path.stem in page  # the good run's row


def test_a_damaged_recording_in_a_subprocess(
        damaged: dict[str, tuple[Path, int, int, str]], run_path: Path) -> None:
    path, number, offset, _reason = damaged["lz4_header"]
    for line in (["analyze", str(path)], ["diff", str(run_path), str(path)]):
        done = subprocess.run([sys.executable, "-m", "ffexp", *line], capture_output=True,
                              text=True, timeout=300, cwd=ROOT)
        check_one_line(done.returncode, done.stderr,
                       [str(path), f"chunk {number} at byte {offset}"])


@pytest.mark.parametrize(("cut", "needle"), [
    (lambda n: 3, "not an MCAP file"),  # not even its magic
    (lambda n: 8, "no topic"),  # the magic, then nothing: no run in it
])
def test_a_truncated_recording(run_path: Path, tmp_path: Path, cut: Callable[[int], int],
                               needle: str) -> None:
    data = run_path.read_bytes()
    path = tmp_path / "cut.mcap"
    path.write_bytes(data[:cut(len(data))])
    result = runner.invoke(app, ["analyze", str(path)])
    check_one_line(result.exit_code, result.stderr, [str(path), needle])


def test_a_summary_without_a_message_s_channel(run_path: Path, tmp_path: Path) -> None:
    """The summary's channel records renumbered (so the chunks' messages name channels
    it does not list): mcap's reader meets a KeyError; every reader says corrupt data
    or reads what the summary lists, never lets the KeyError through."""
    path = tmp_path / "renumbered.mcap"
    rewrite(run_path, path, CompressionType.ZSTD)
    data = bytearray(path.read_bytes())
    (summary_start,) = struct.unpack_from("<Q", data, len(data) - 8 - 29 + 9)
    pos, end = summary_start, len(data) - 8 - 29
    while pos < end:  # opcode 0x04: a channel record, its id the first field (u16)
        op, length = struct.unpack_from("<BQ", data, pos)
        if op == 0x04:
            struct.pack_into("<H", data, pos + 9, 1000 + struct.unpack_from("<H", data,
                                                                           pos + 9)[0])
        pos += 9 + length
    path.write_bytes(bytes(data))
    with pytest.raises(InputError, match=r"renumbered\.mcap: corrupt data"):
        load_with_mcap(path)
    rec = load(path)  # the chunks' own records are read: none of their channels is listed
    assert not any(len(t) for t in rec.topics.values())
    assert contents(path).rows


def test_a_log_time_past_int64_loads_alike(tmp_path: Path) -> None:
    """MCAP's times are unsigned: both readers take one past 2**63 as int64 (wrapped),
    mcap's objects' path no longer fails on it."""
    path = tmp_path / "late.mcap"
    with path.open("wb") as fh:
        w = Writer(fh)
        w.start()
        cid = w.register_channel("/events", "json", 0)
        for t in (5, 2**63 + 7):
            w.add_message(cid, t, b"{}", t)
        w.finish()
    want = [5, 2**63 + 7 - 2**64]
    assert load(path).json["/events"].log_time_ns.tolist() == sorted(want)
    assert load_with_mcap(path).json["/events"].log_time_ns.tolist() == sorted(want)
