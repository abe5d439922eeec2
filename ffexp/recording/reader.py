"""Reading run recordings back: fast ``load`` into numpy (and pandas frames on request,
``Recording.frame``), and recovery of files whose writer never finished.

A finished file is read through its summary: topic and time-range selection
use the chunk index, so only the chunks that hold the wanted topics and times are
read; their messages are found and decoded a topic at once, with no Python object
per message (:mod:`ffexp.recording.chunks`, :mod:`ffexp.recording.columns`).
:func:`load_with_mcap` reads the same through mcap's ``iter_messages`` (an object
per message), the reference ``load`` is tested and measured against. An unfinished
file (killed run) has no footer; it is read record by record from the start, keeping
every complete chunk, until the stream ends (``EndOfFile``) or breaks off in the
middle of a record (``struct.error``). Chunk CRCs are checked: a finished file with
a corrupt chunk (one that does not decompress, zstd or lz4, whose CRC does not match,
or whose records do not fit in it) is a :class:`CorruptRecordingError` naming the file
and the chunk and pointing to ``ffexp recover``, which rewrites every chunk but the
corrupt ones; nothing raises a library's own error.
"""

from __future__ import annotations

import json
import struct
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from mcap.exceptions import EndOfFile, McapError
from mcap.reader import make_reader
from mcap.records import Attachment, Channel, Chunk, Message, Metadata, Schema
from mcap.stream_reader import CRCValidationError, StreamReader, breakup_chunk
from mcap.summary import Summary
from mcap.writer import CompressionType, Writer
from zstandard import ZstdError

from drivers.config import not_regular
from ffexp.errors import CorruptRecordingError, InputError
from ffexp.recording import attached
from ffexp.recording.chunks import (
    ChannelMessages,
    ChunkError,
    decompression_failed,
    read_messages,
)
from ffexp.recording.columns import decode_channels
from ffexp.recording.data import JsonData, Recording, TopicData, spec_from_schema

__all__ = [
    "RECOVERY_METADATA", "RUN_END_TOPIC", "Contents", "JsonData", "Recording", "RecoverResult",
    "TopicData", "check_file", "contents", "load", "load_with_mcap", "recover", "run_seconds",
    "spec_from_schema",
]

MAGIC = b"\x89MCAP0\r\n"
# OSError: a file shorter than a footer cannot even be seeked to its summary
_READ_ERRORS = (EndOfFile, McapError, struct.error, ValueError, MemoryError, OSError)
# a chunk whose data cannot be decompressed, or whose CRC does not match (a ValueError),
# or whose records mcap cannot parse (a length past any buffer: OverflowError); lz4's
# errors are plain RuntimeErrors (``_damaged``)
_CHUNK_ERRORS = (ZstdError, McapError, struct.error, ValueError, MemoryError, OverflowError)


def _damaged(exc: BaseException) -> bool:
    """Whether ``exc`` is what reading a damaged chunk raises (and not a bug)."""
    return isinstance(exc, _CHUNK_ERRORS) or decompression_failed(exc)


def check_file(path: Path) -> None:
    """An :class:`InputError` naming ``path`` unless it is a readable MCAP file (by its
    magic bytes; nothing else is read)."""
    _check_magic(path)


def _check_magic(path: Path) -> None:
    odd = not_regular(path)
    if odd:
        raise InputError(f"{path}: is {odd}, not a regular MCAP file")
    try:
        with path.open("rb") as fh:
            head = fh.read(len(MAGIC))
    except FileNotFoundError:
        raise InputError(f"{path}: file not found") from None
    except IsADirectoryError:
        raise InputError(f"{path}: is a directory, expected an MCAP file") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read: {exc.strerror}") from None
    if not head:
        raise InputError(f"{path}: empty file, not an MCAP recording")
    if head != MAGIC:
        raise InputError(f"{path}: not an MCAP file")


@dataclass
class _Stream:
    """Everything readable from a file, in file order."""

    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    messages: list[Message] = field(default_factory=list)
    metadata: list[Metadata] = field(default_factory=list)
    attachments: list[Attachment] = field(default_factory=list)
    complete: bool = False
    error: str = ""
    corrupt: list[int] = field(default_factory=list)
    """Numbers (from 1) of the chunks left out: their data is corrupt."""
    columns: dict[int, ChannelMessages] | None = None
    """The messages by channel, read chunk by chunk (then ``messages`` is empty)."""


def _records(reader: StreamReader, out: _Stream) -> Iterator[Any]:
    """The reader's records, each chunk's broken up; a corrupt chunk is left out (and
    numbered in ``out.corrupt``) and the stream goes on after it."""
    n = 0
    for rec in reader.records:
        if not isinstance(rec, Chunk):
            yield rec
            continue
        n += 1
        try:
            inner = breakup_chunk(rec, validate_crc=True)
        except Exception as exc:
            if not _damaged(exc):
                raise
            out.corrupt.append(n)
            continue
        yield from inner


def _read_stream(path: Path) -> _Stream:
    """Read every complete record of a (possibly unfinished) file, but corrupt chunks."""
    out = _Stream()
    with path.open("rb") as fh:
        try:
            for rec in _records(StreamReader(fh, validate_crcs=True, emit_chunks=True), out):
                if isinstance(rec, Schema):
                    out.schemas[rec.id] = rec
                elif isinstance(rec, Channel):
                    out.channels[rec.id] = rec
                elif isinstance(rec, Message):
                    out.messages.append(rec)
                elif isinstance(rec, Metadata):
                    out.metadata.append(rec)
                elif isinstance(rec, Attachment):
                    out.attachments.append(rec)
            out.complete = True
        except _READ_ERRORS as exc:
            out.error = type(exc).__name__
    return out


def _finished_messages(
    path: Path, topics: list[str] | None, start_ns: int | None, end_ns: int | None,
    extra: list[str], fast: bool,
) -> tuple[_Stream, bool]:
    """Read a finished file through its index; (stream, False) if it has none. ``topics``
    gets the topics its attached frames need (:func:`attached.helpers`), also in
    ``extra``. ``fast``: the messages as columns (:func:`read_messages`), else as mcap's
    ``Message`` objects."""
    out = _Stream(complete=True)
    summary = None
    with path.open("rb") as fh:
        try:
            reader = make_reader(fh, validate_crcs=True)
            summary = reader.get_summary()
            if summary is None:
                return out, False
            if topics is not None:
                extra += attached.helpers(topics, (c.topic for c in summary.channels.values()))
                topics += extra
            out.channels = dict(summary.channels)
            out.schemas = dict(summary.schemas)
            if topics is not None:
                out.channels = {k: c for k, c in out.channels.items() if c.topic in topics}
            if fast and summary.chunk_indexes:  # else mcap reads the file from its start
                ids = None if topics is None else set(out.channels)
                out.columns = read_messages(fh, summary, ids, start_ns, end_ns)
            else:
                # file order is cheaper than the reader's merge by time; each topic
                # is sorted by log time when it is decoded
                kwargs: dict[str, Any] = {"topics": topics, "log_time_order": False}
                if start_ns is not None:
                    kwargs["starting_at"] = start_ns
                if end_ns is not None:
                    kwargs["ending_before"] = end_ns
                try:
                    out.messages = [m for _s, _c, m in reader.iter_messages(**kwargs)]
                except KeyError as exc:  # mcap's reader met a channel the summary lacks
                    raise McapError(f"a message of channel {exc}, which the summary does "
                                    "not list") from None
            out.metadata = [
                Metadata(name=m.name, metadata=m.metadata) for m in reader.iter_metadata()
            ]
            out.attachments = list(reader.iter_attachments())
        except Exception as exc:
            if summary is not None and _damaged(exc):
                raise CorruptRecordingError(str(path), _why(exc)) from None
            if not (isinstance(exc, _READ_ERRORS) or _damaged(exc)):
                raise
            return _Stream(), False
    return out, True


def _why(exc: BaseException) -> str:
    """A read error in a few words: its class, and its message when short."""
    if isinstance(exc, ChunkError):
        return str(exc)
    if isinstance(exc, CRCValidationError):
        return "a chunk's CRC does not match its data"
    if isinstance(exc, ZstdError) or decompression_failed(exc):
        return "a chunk does not decompress"
    text = str(exc).splitlines()[0] if str(exc) else ""
    return f"{type(exc).__name__}: {text}" if text and len(text) < 120 else type(exc).__name__


def load(
    path: Path | str,
    topics: Iterable[str] | None = None,
    start_ns: int | None = None,
    end_ns: int | None = None,
) -> Recording:
    """Load a recording into numpy arrays per topic.

    Args:
        path: the MCAP file.
        topics: only these topics (default: all).
        start_ns, end_ns: only messages with ``start_ns <= log_time < end_ns``.

    An unfinished file loads what it holds, with ``complete = False`` and a
    warning. Raises :class:`InputError` for a missing, empty or non-MCAP file.
    """
    return _load(Path(path), topics, start_ns, end_ns, fast=True)


def load_with_mcap(
    path: Path | str,
    topics: Iterable[str] | None = None,
    start_ns: int | None = None,
    end_ns: int | None = None,
) -> Recording:
    """:func:`load` with a finished file's messages read through mcap's own
    ``SeekingReader.iter_messages`` (a ``Message`` object per message, decoded from
    those): how ``load`` read before it read chunks itself, kept as the reference
    its tests and ``benchmarks/bench_load.py`` compare it with."""
    return _load(Path(path), topics, start_ns, end_ns, fast=False)


def _load(path: Path, topics: Iterable[str] | None, start_ns: int | None,
          end_ns: int | None, fast: bool) -> Recording:
    _check_magic(path)
    asked = None if topics is None else list(topics)
    wanted = None if asked is None else list(asked)
    extra: list[str] = []
    stream, indexed = _finished_messages(path, wanted, start_ns, end_ns, extra, fast)
    rec = Recording(path=path)
    cut = ""
    if not indexed:
        stream = _read_stream(path)
        if asked is not None:
            extra = attached.helpers(asked, (c.topic for c in stream.channels.values()))
            wanted = asked + extra
        rec.complete = False
        last = max((m.log_time for m in stream.messages), default=None)
        cut = (f"{path}: recording is incomplete ({stream.error or 'no summary'}); "
               f"read {len(stream.messages)} messages")
        if stream.corrupt:
            rec.warnings.append(f"{path}: corrupt chunk(s) {_numbers(stream.corrupt)} left out")
        stream.messages = [
            m
            for m in stream.messages
            if stream.channels.get(m.channel_id) is not None
            and (wanted is None or stream.channels[m.channel_id].topic in wanted)
            and (start_ns is None or m.log_time >= start_ns)
            and (end_ns is None or m.log_time < end_ns)
        ]
    if stream.columns is not None:
        decode_channels(rec, stream.channels, stream.schemas, stream.columns)
    else:
        _decode_into(rec, stream)
    _records_into(rec, stream)
    if start_ns is not None:  # the attached frames were written at the run's start
        fixed = [c.topic for c in stream.channels.values() if attached.is_attached(c.topic)
                 and not len(rec.json.get(c.topic, ()))]
        if fixed:
            rec.json.update(_load(path, fixed, None, None, fast).json)
    attached.resolve(rec, extra)
    if cut:  # times in the run's seconds (its first cycle is 0), as everywhere else
        upto = "" if last is None else f" up to {run_seconds(rec, last):.3f} s of the run"
        rec.warnings.insert(0, f"{cut}{upto}; `ffexp recover` rewrites it")
    _check_holes(rec)
    if wanted is None or RUN_END_TOPIC in wanted:
        _check_run_end(rec)
    return rec


def run_seconds(rec: Recording, log_time_ns: int) -> float:
    """A log time as seconds since the run's start (:attr:`Recording.run_start_ns`)."""
    return (log_time_ns - rec.run_start_ns) / 1e9


#: Metadata ``ffexp recover`` adds when it left corrupt chunks out.
RECOVERY_METADATA = "recovery"
#: The topic whose last phase, DONE or ABORT, says a run recording holds the run's end.
RUN_END_TOPIC = "/runner/phase"
_END_PHASES = frozenset({"DONE", "ABORT"})


def _check_holes(rec: Recording) -> None:
    """A file ``ffexp recover`` rewrote without some corrupt chunks is not complete."""
    hole = rec.metadata.get(RECOVERY_METADATA, {}).get("corrupt_chunks")
    if hole:
        rec.complete = False
        rec.warnings.append(f"{rec.path}: recovered without corrupt chunk(s) {hole} of "
                            f"{rec.metadata[RECOVERY_METADATA].get('source', 'its source')}: "
                            "their data is missing")


def _check_run_end(rec: Recording) -> None:
    """A run's recording (one with ``run`` metadata) whose end was never written (no DONE
    or ABORT on :data:`RUN_END_TOPIC`: the process was killed, the file recovered or cut)
    is not complete, whether or not the file itself was finished (``ffexp recover``)."""
    if "run" not in rec.metadata:
        return  # not a run (a friction video's recording, ...): no phases to end
    phases = rec.json.get(RUN_END_TOPIC)
    if phases is not None and any(m.get("phase") in _END_PHASES for m in phases.messages):
        return
    if rec.complete:  # a finished (recovered) file: say why it still is incomplete
        rec.warnings.append(
            f"{rec.path}: the run's end is not recorded (no DONE or ABORT on "
            f"{RUN_END_TOPIC}): the run ended abnormally")
    rec.complete = False


def _decode_into(rec: Recording, stream: _Stream) -> None:
    """The stream's messages (mcap's objects) into ``rec``."""
    by_channel: dict[int, list[Message]] = {}
    for m in stream.messages:
        by_channel.setdefault(m.channel_id, []).append(m)
    for cid, channel in stream.channels.items():
        msgs = by_channel.get(cid, [])
        schema = stream.schemas.get(channel.schema_id)
        # MCAP's times are unsigned; as int64, as the chunk reader takes them
        times = np.fromiter((m.log_time for m in msgs), dtype=np.uint64,
                            count=len(msgs)).view(np.int64)
        if times.size > 1 and np.any(np.diff(times) < 0):
            order = np.argsort(times, kind="stable")
            times = times[order]
            msgs = [msgs[i] for i in order]
        if channel.message_encoding == "cdr" and schema is not None:
            spec = spec_from_schema(schema)
            if spec is None:
                rec.warnings.append(f"{rec.path}: {channel.topic}: schema {schema.name} skipped")
                continue
            dtype = spec.dtype
            if any(len(m.data) != dtype.itemsize for m in msgs):
                rec.warnings.append(
                    f"{rec.path}: {channel.topic}: messages do not match {schema.name}; skipped"
                )
                continue
            arr = np.frombuffer(b"".join(m.data for m in msgs), dtype=dtype)
            rec.topics[channel.topic] = TopicData(
                times, {f.name: arr[f.name].copy() for f in spec.fields}
            )
        elif channel.message_encoding == "json":
            try:
                decoded = [json.loads(m.data) for m in msgs]
            except (json.JSONDecodeError, UnicodeDecodeError):
                rec.warnings.append(f"{rec.path}: {channel.topic}: invalid JSON; skipped")
                continue
            rec.json[channel.topic] = JsonData(times, decoded)
        else:
            rec.warnings.append(
                f"{rec.path}: {channel.topic}: encoding {channel.message_encoding!r} skipped"
            )


def _records_into(rec: Recording, stream: _Stream) -> None:
    """The stream's metadata and attachments into ``rec``."""
    for md in stream.metadata:
        rec.metadata[md.name] = dict(md.metadata)
    for att in stream.attachments:
        rec.attachments[att.name] = bytes(att.data)


@dataclass(frozen=True)
class RecoverResult:
    """What :func:`recover` salvaged."""

    messages: int
    channels: int
    complete: bool
    last_log_time_ns: int | None
    corrupt_chunks: tuple[int, ...] = ()
    """The chunks left out (numbered from 1): their data was corrupt."""


def recover(src: Path, dst: Path) -> RecoverResult:
    """Rewrite every complete record of ``src`` as a valid, indexed ``dst``."""
    _check_magic(src)
    if src.resolve() == dst.resolve():
        raise InputError(f"{dst}: output must differ from the input")
    stream = _read_stream(src)
    try:
        fh = dst.open("wb")
    except OSError as exc:
        raise InputError(f"{dst}: cannot write: {exc.strerror}") from None
    with fh:
        writer = Writer(fh, compression=CompressionType.ZSTD)
        writer.start(profile="ffexp", library="ffexp recover")
        schema_ids: dict[int, int] = {}
        channel_ids: dict[int, int] = {}
        for sid, schema in stream.schemas.items():
            schema_ids[sid] = writer.register_schema(schema.name, schema.encoding, schema.data)
        for cid, ch in stream.channels.items():
            channel_ids[cid] = writer.register_channel(
                ch.topic, ch.message_encoding, schema_ids.get(ch.schema_id, 0), dict(ch.metadata)
            )
        for m in _in_order(stream.messages):
            if m.channel_id in channel_ids:
                writer.add_message(
                    channel_ids[m.channel_id], m.log_time, m.data, m.publish_time, m.sequence
                )
        for md in stream.metadata:
            writer.add_metadata(md.name, dict(md.metadata))
        if stream.corrupt:  # the hole stays known: such a file is not complete
            writer.add_metadata(RECOVERY_METADATA, {
                "source": str(src), "corrupt_chunks": _numbers(stream.corrupt)})
        for att in stream.attachments:
            writer.add_attachment(att.create_time, att.log_time, att.name, att.media_type, att.data)
        writer.finish()  # type: ignore[no-untyped-call]
    last = max((m.log_time for m in stream.messages), default=None)
    return RecoverResult(len(stream.messages), len(stream.channels), stream.complete, last,
                         tuple(stream.corrupt))


def _numbers(ns: list[int]) -> str:
    return ", ".join(str(n) for n in ns)


def _in_order(messages: list[Message]) -> Iterator[Message]:
    return iter(sorted(messages, key=lambda m: m.log_time))


@dataclass
class Contents:
    """What a recording holds (``ffexp topics FILE``): one row per topic."""

    path: Path
    complete: bool
    span_s: float | None
    rows: list[dict[str, Any]]
    warnings: list[str]


def _attached_frames(fh: Any, summary: Summary, path: Path, warnings: list[str],
                     ) -> dict[str, bytes]:
    """The attached frames' last messages by topic, read through the summary's chunk
    index; a corrupt chunk adds a warning (they then stay unresolved), never an error."""
    ids = {cid for cid, c in summary.channels.items() if attached.is_attached(c.topic)}
    try:
        got = read_messages(fh, summary, ids) if ids else {}
    except ChunkError as exc:
        warnings.append(f"{path}: corrupt data ({exc}); `ffexp recover {path}` rewrites "
                        "every readable chunk into a new file")
        return {}
    out = {}
    for cid, msgs in got.items():
        if len(msgs):  # the last by log time, as mcap's reader orders them
            times = msgs.log_time_ns
            out[summary.channels[cid].topic] = msgs.payloads()[
                len(times) - 1 - int(np.argmax(times[::-1]))]
    return out


def contents(path: Path) -> Contents:
    """Topics, message counts, rates and time span of a recording.

    A finished file answers from its summary (statistics and channels, no
    message is decompressed); an unfinished one is read record by record.
    Times are seconds since the first message of the file.
    """
    _check_magic(path)
    counts: dict[str, int] = {}
    first: dict[str, int] = {}
    last: dict[str, int] = {}
    schema_of: dict[str, str] = {}
    fixed: dict[str, bytes] = {}  # the attached frames' messages by topic
    complete = False
    warnings: list[str] = []
    with path.open("rb") as fh:
        try:
            summary = make_reader(fh, validate_crcs=True).get_summary()
        except _READ_ERRORS:
            summary = None
        if summary is not None and summary.chunk_indexes:
            fixed.update(_attached_frames(fh, summary, path, warnings))
    if summary is not None:
        complete = True
        stats = summary.statistics
        for cid, ch in summary.channels.items():
            counts[ch.topic] = counts.get(ch.topic, 0) + (
                stats.channel_message_counts.get(cid, 0) if stats else 0
            )
            schema = summary.schemas.get(ch.schema_id)
            schema_of[ch.topic] = schema.name if schema is not None else ""
        for idx in summary.chunk_indexes:
            for cid in idx.message_index_offsets:
                if cid not in summary.channels:
                    continue  # a damaged summary: counted from the statistics only
                topic = summary.channels[cid].topic
                first[topic] = min(first.get(topic, idx.message_start_time),
                                   idx.message_start_time)
                last[topic] = max(last.get(topic, idx.message_end_time), idx.message_end_time)
    if summary is None or not summary.chunk_indexes:
        stream = _read_stream(path)
        complete = complete and stream.complete
        if summary is None:
            warnings.append(f"{path}: recording is incomplete; `ffexp recover` rewrites it")
        if stream.corrupt:
            warnings.append(f"{path}: corrupt chunk(s) {_numbers(stream.corrupt)} left out")
        counts = {ch.topic: 0 for ch in stream.channels.values()}
        for ch in stream.channels.values():
            schema = stream.schemas.get(ch.schema_id)
            schema_of[ch.topic] = schema.name if schema is not None else ""
        for m in stream.messages:
            mch = stream.channels.get(m.channel_id)
            if mch is None:
                continue
            if attached.is_attached(mch.topic):
                fixed[mch.topic] = m.data
            counts[mch.topic] += 1
            first[mch.topic] = min(first.get(mch.topic, m.log_time), m.log_time)
            last[mch.topic] = max(last.get(mch.topic, m.log_time), m.log_time)
    for site, body in attached.sites_of(fixed).items():  # resolved on reading: as its body
        if site not in counts and body in counts:
            counts[site] = counts[body]
            for times in (first, last):
                if body in times:
                    times[site] = times[body]
            schema_of[site] = f"{attached.FRAME_SCHEMA} (resolved from {body})"
    t0 = min(first.values(), default=None)
    t1 = max(last.values(), default=None)
    rows = []
    for topic in sorted(counts):
        n = counts[topic]
        a, b = first.get(topic), last.get(topic)
        span = (b - a) / 1e9 if a is not None and b is not None else None
        rows.append({
            "topic": topic,
            "messages": n,
            "rate_hz": (n - 1) / span if span and n > 1 else None,
            "first_s": (a - t0) / 1e9 if a is not None and t0 is not None else None,
            "last_s": (b - t0) / 1e9 if b is not None and t0 is not None else None,
            "schema": schema_of.get(topic, ""),
        })
    span_s = (t1 - t0) / 1e9 if t0 is not None and t1 is not None else None
    return Contents(path, complete, span_s, rows, warnings)
