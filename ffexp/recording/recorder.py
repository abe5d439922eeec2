"""Writing a run to one MCAP file, crash-safe.

The writer is ``mcap.writer.Writer`` with zstd chunks of 1 MiB (mcap's own
default, which its chunk-size study found flat in ratio and speed from
256 KiB to 32 MiB while keeping reader memory low). Chunk size alone would
bound crash loss only by size; :class:`Recorder` therefore also closes the
open chunk and flushes the file at least every ``flush_interval_s`` of wall
time (default 1 s), so a killed process loses at most about a second of data.

Messages go through :class:`FastWriter`, mcap's ``Writer`` whose ``add_message``
writes the very same bytes (record, chunk index, statistics) with one
``struct.pack`` instead of mcap's field-by-field record writer: about 2.5 times
faster per message (``benchmarks/bench_recording.py``). It uses the ``Writer``'s
private chunk builder and statistics; if a future mcap lacks them, it falls back
to mcap's own ``add_message`` (``tests/test_recording_writer.py`` checks that
both write identical files).
"""

from __future__ import annotations

import json
import math
import struct
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from types import TracebackType
from typing import IO, Any

import numpy as np
from mcap.opcode import Opcode
from mcap.records import MessageIndex
from mcap.writer import CompressionType, Writer

from drivers.base.types import NS_PER_S
from ffexp.errors import InputError
from ffexp.recording.topics import CDR_TOPICS, JSON_TOPICS, LOG_LEVELS

CHUNK_SIZE_BYTES = 1 << 20
PROFILE = "ffexp"

#: An MCAP Message record's head: opcode, record length, channel id, sequence,
#: log time, publish time (the MCAP specification's field order, little endian).
_MESSAGE_HEAD = struct.Struct("<BQHIQQ")
_MESSAGE_FIXED = _MESSAGE_HEAD.size - 9  # the record length counts what follows it
_OPCODE_MESSAGE = int(Opcode.MESSAGE)


class FastWriter(Writer):
    """``mcap.writer.Writer`` with a faster :meth:`add_message` (same bytes).

    Everything else (schemas, channels, chunking, compression, indexes, summary)
    is mcap's. ``fast`` is False when this mcap has not the private state used.
    """

    def __init__(self, output: IO[bytes], **kw: Any) -> None:
        super().__init__(output, **kw)
        chunks = getattr(self, "_Writer__chunk_builder", None)
        stats = getattr(self, "_Writer__statistics", None)
        finalize = getattr(self, "_Writer__maybe_finalize_chunk", None)
        buffer = getattr(getattr(chunks, "record_writer", None), "_buffer", None)
        self.fast = (chunks is not None and stats is not None and callable(finalize)
                     and buffer is not None and hasattr(chunks, "message_indices"))
        self._chunks: Any = chunks
        self._stats: Any = stats
        self._finalize: Any = finalize

    def add_message(self, channel_id: int, log_time: int, data: bytes, publish_time: int,
                    sequence: int = 0) -> None:
        if not self.fast:
            super().add_message(channel_id, log_time, data, publish_time, sequence)
            return
        st, cb = self._stats, self._chunks
        if st.message_count == 0 or log_time < st.message_start_time:
            st.message_start_time = log_time
        if log_time > st.message_end_time:
            st.message_end_time = log_time
        st.channel_message_counts[channel_id] += 1
        st.message_count += 1
        if cb.num_messages == 0 or log_time < cb.message_start_time:
            cb.message_start_time = log_time
        if log_time > cb.message_end_time:
            cb.message_end_time = log_time
        index = cb.message_indices.get(channel_id)
        if index is None:
            index = cb.message_indices[channel_id] = MessageIndex(channel_id=channel_id,
                                                                  records=[])
        buf = cb.record_writer._buffer  # the chunk builder's record stream (a BytesIO)
        index.records.append((log_time, buf.tell()))
        cb.num_messages += 1
        buf.write(_MESSAGE_HEAD.pack(_OPCODE_MESSAGE, _MESSAGE_FIXED + len(data), channel_id,
                                     sequence, log_time, publish_time))
        buf.write(data)
        self._finalize()


def _stamp(time_ns: int) -> dict[str, int]:
    sec, nsec = divmod(time_ns, NS_PER_S)
    return {"sec": sec, "nsec": nsec}


def pose_to_transform(pose: np.ndarray) -> tuple[dict[str, float], dict[str, float]]:
    """Translation and unit quaternion (x, y, z, w) of a 4x4 pose.

    Written out (Shepperd's method) because ``scipy``'s ``Rotation.from_matrix``
    costs about 0.25 ms a call here, which the per-cycle log cannot afford.
    """
    r = pose[:3, :3]
    tr = float(r[0, 0] + r[1, 1] + r[2, 2])
    if tr > 0.0:
        s = 2.0 * math.sqrt(tr + 1.0)
        q = [(r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, 0.25 * s]
    else:
        i = int(np.argmax(np.diag(r)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(max(1.0 + r[i, i] - r[j, j] - r[k, k], 1e-300))
        q = [0.0, 0.0, 0.0, (r[k, j] - r[j, k]) / s]
        q[i] = 0.25 * s
        q[j] = (r[j, i] + r[i, j]) / s
        q[k] = (r[k, i] + r[i, k]) / s
    t = {"x": float(pose[0, 3]), "y": float(pose[1, 3]), "z": float(pose[2, 3])}
    return t, {"x": float(q[0]), "y": float(q[1]), "z": float(q[2]), "w": float(q[3])}


class Recorder:
    """One run's MCAP file. Use as a context manager; :meth:`finish` always runs.

    Args:
        path: the file to create (parent directories are made).
        flush_interval_s: wall-clock bound on unflushed data.
        clock: wall clock in seconds (injectable for tests).

    High-rate topics are written from preallocated records: fill
    ``rec = recorder.record(topic)`` and call ``recorder.write(topic, time_ns)``.
    """

    def __init__(
        self,
        path: Path,
        *,
        flush_interval_s: float = 1.0,
        chunk_size: int = CHUNK_SIZE_BYTES,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.path = path
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            self._fh: IO[bytes] = path.open("wb")
        except OSError as exc:
            raise InputError(f"{path}: cannot create recording: {exc.strerror}") from None
        self._writer = FastWriter(self._fh, chunk_size=chunk_size,
                                  compression=CompressionType.ZSTD)
        self._writer.start(profile=PROFILE, library="ffexp")
        self._clock = clock
        self._flush_interval_s = flush_interval_s
        self._last_flush = clock()
        self._channels: dict[str, int] = {}
        self._records: dict[str, np.ndarray] = {}
        self._names: dict[str, tuple[str, ...]] = {}
        self._seq: dict[str, int] = {}
        self._add_message = self._writer.add_message
        self._plans: dict[tuple[str, type], tuple[tuple[str, np.ndarray], ...]] = {}
        self.message_count = 0
        self.finished = False
        self.taps: list[Callable[[str, int, bytes], None]] = []
        """Called with ``(topic, log_time_ns, message bytes)`` for every message written
        (a live viewer); they must return at once. Empty: no cost."""

    # -- channels -------------------------------------------------------------
    def _channel(self, topic: str) -> int:
        cid = self._channels.get(topic)
        if cid is not None:
            return cid
        if topic in CDR_TOPICS:
            spec = CDR_TOPICS[topic].spec
            sid = self._writer.register_schema(spec.name, "ros2msg", spec.ros2msg.encode())
            cid = self._writer.register_channel(topic, "cdr", sid)
        elif topic in JSON_TOPICS:
            jt = JSON_TOPICS[topic]
            sid = self._writer.register_schema(jt.schema_name, "jsonschema", jt.schema_bytes)
            cid = self._writer.register_channel(topic, "json", sid)
        else:
            raise KeyError(f"unknown topic {topic!r}: add it to ffexp/recording/topics.py")
        self._channels[topic] = cid
        self._seq[topic] = 0
        return cid

    def record(self, topic: str) -> np.ndarray:
        """The preallocated one-element record of a CDR topic (fill, then :meth:`write`)."""
        rec = self._records.get(topic)
        if rec is None:
            rec = CDR_TOPICS[topic].spec.new_record()
            self._records[topic] = rec
        return rec

    # -- writing --------------------------------------------------------------
    def _add(self, topic: str, time_ns: int, data: bytes) -> None:
        if time_ns < 0:
            raise ValueError(f"{topic}: negative log time {time_ns} ns")
        cid = self._channels.get(topic)
        if cid is None:
            cid = self._channel(topic)
        seq = self._seq[topic]
        self._seq[topic] = seq + 1
        self._add_message(cid, time_ns, data, time_ns, seq)
        self.message_count += 1
        for tap in self.taps:
            tap(topic, time_ns, data)
        if self._clock() - self._last_flush >= self._flush_interval_s:
            self.flush()

    def write(self, topic: str, time_ns: int) -> None:
        """Write the current contents of :meth:`record` for ``topic``."""
        self._add(topic, time_ns, self._records[topic].tobytes())

    def write_fields(self, topic: str, time_ns: int, source: object) -> None:
        """Write a CDR topic whose fields are attributes of ``source`` by the same
        names (arrays are flattened row-major, e.g. a 4x4 pose into 16 numbers)."""
        rec = self._records.get(topic)
        if rec is None:
            rec = self.record(topic)
        key = (topic, type(source))
        plan = self._plans.get(key)
        if plan is None:
            plan = self._plans[key] = self._plan(rec, self._field_names(topic), source)
        try:
            for name, view in plan:
                view[...] = getattr(source, name)
        except ValueError:  # a field's shape changed: assign it flattened
            ndarray = np.ndarray
            for name in self._field_names(topic):
                value = getattr(source, name)
                rec[name] = value.reshape(-1) if isinstance(value, ndarray) else value
        self.write(topic, time_ns)

    @staticmethod
    def _plan(rec: np.ndarray, names: tuple[str, ...],
              source: object) -> tuple[tuple[str, np.ndarray], ...]:
        """Per field, a view of the record shaped like ``source``'s value (a 4x4 pose
        into its 16 numbers), so that filling is one assignment per field."""
        plan = []
        for name in names:
            field = rec[name]  # (1,) for a scalar field, (1, n) for an array field
            value = getattr(source, name)
            if field.ndim == 2:
                field = field[0]
                if isinstance(value, np.ndarray) and value.size == field.size:
                    shaped = field.reshape(value.shape)
                    if np.shares_memory(shaped, rec):  # a view, not a copy
                        field = shaped
            plan.append((name, field))
        return tuple(plan)

    def _field_names(self, topic: str) -> tuple[str, ...]:
        names = self._names.get(topic)
        if names is None:
            names = tuple(f.name for f in CDR_TOPICS[topic].spec.fields)
            self._names[topic] = names
        return names

    def write_records(self, topic: str, times_ns: np.ndarray, records: np.ndarray) -> None:
        """Write many messages of one CDR topic (e.g. all F/T samples of a cycle)."""
        size = records.dtype.itemsize
        blob = records.tobytes()
        times = times_ns.tolist()
        if not times:
            return
        if min(times) < 0:
            raise ValueError(f"{topic}: negative log time {min(times)} ns")
        cid = self._channels.get(topic)
        if cid is None:
            cid = self._channel(topic)
        seq = self._seq[topic]
        add = self._add_message
        taps = self.taps
        for i, t in enumerate(times):
            msg = blob[i * size : (i + 1) * size]
            add(cid, t, msg, t, seq + i)
            for tap in taps:
                tap(topic, t, msg)
        self._seq[topic] = seq + len(times)
        self.message_count += len(times)
        if self._clock() - self._last_flush >= self._flush_interval_s:
            self.flush()

    def write_json(self, topic: str, time_ns: int, message: Mapping[str, Any]) -> None:
        """Write one JSON message on a low-rate topic."""
        self._add(topic, time_ns, json.dumps(message, separators=(",", ":")).encode())

    def log(self, time_ns: int, level: str, name: str, message: str) -> None:
        """An event as ``foxglove.Log`` on ``/events`` (level DEBUG..FATAL)."""
        self.write_json(
            "/events",
            time_ns,
            {
                "timestamp": _stamp(time_ns),
                "level": LOG_LEVELS[level],
                "message": message,
                "name": name,
                "file": "",
                "line": 0,
            },
        )

    def transform(self, time_ns: int, parent: str, child: str, pose: np.ndarray) -> None:
        """A ``foxglove.FrameTransform`` of ``child`` in ``parent`` on ``/tf``.

        Formatted directly (frame names are plain identifiers, numbers finite):
        ``json.dumps`` of the same dict costs ten times more per cycle.
        """
        t, q = pose_to_transform(pose)
        if not all(math.isfinite(v) for v in (*t.values(), *q.values())):
            raise ValueError(f"/tf: {child} pose is not finite")
        sec, nsec = divmod(time_ns, NS_PER_S)
        text = (
            f'{{"timestamp":{{"sec":{sec},"nsec":{nsec}}},'
            f'"parent_frame_id":{json.dumps(parent)},"child_frame_id":{json.dumps(child)},'
            f'"translation":{{"x":{t["x"]!r},"y":{t["y"]!r},"z":{t["z"]!r}}},'
            f'"rotation":{{"x":{q["x"]!r},"y":{q["y"]!r},"z":{q["z"]!r},"w":{q["w"]!r}}}}}'
        )
        self._add("/tf", time_ns, text.encode())

    def metadata(self, name: str, values: Mapping[str, str]) -> None:
        """An MCAP metadata record (string to string map)."""
        self._writer.add_metadata(name, dict(values))

    def attach(self, name: str, data: bytes, media_type: str, time_ns: int) -> None:
        """An MCAP attachment, e.g. the protocol file as run."""
        self._writer.add_attachment(time_ns, time_ns, name, media_type, data)

    # -- lifetime -------------------------------------------------------------
    def flush(self) -> None:
        """Close the open chunk and push everything to the OS."""
        if self.finished:
            return
        self._writer.flush()  # type: ignore[no-untyped-call]
        self._fh.flush()
        self._last_flush = self._clock()

    def finish(self) -> None:
        """Write the summary and close the file; idempotent."""
        if self.finished:
            return
        self.finished = True
        try:
            self._writer.finish()  # type: ignore[no-untyped-call]
        finally:
            self._fh.close()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.finish()
