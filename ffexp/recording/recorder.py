"""Writing a run to one MCAP file, crash-safe.

The writer is ``mcap.writer.Writer`` with zstd chunks of 1 MiB (mcap's own
default, which its chunk-size study found flat in ratio and speed from
256 KiB to 32 MiB while keeping reader memory low). Chunk size alone would
bound crash loss only by size; :class:`Recorder` therefore also closes the
open chunk and flushes the file at least every ``flush_interval_s`` of wall
time (default 1 s), so a killed process loses at most about a second of data.

Messages go through :class:`~ffexp.recording.mcap_writer.FastWriter`, mcap's
``Writer`` with a faster way in for messages that writes the very same bytes
(``benchmarks/bench_recording.py`` measures it). CDR messages are encoded
without numpy records where the values allow it (:meth:`Recorder.layout`,
:class:`~ffexp.recording.encode.FieldsEncoder`).
"""

from __future__ import annotations

import json
import math
import struct
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import IO, Any

import numpy as np
from mcap.writer import CompressionType

from drivers.base.types import NS_PER_S
from ffexp.errors import InputError
from ffexp.recording.encode import FieldsEncoder
from ffexp.recording.mcap_writer import FastWriter, encode_rows
from ffexp.recording.topics import CDR_TOPICS, JSON_TOPICS, LOG_LEVELS

CHUNK_SIZE_BYTES = 1 << 20
PROFILE = "ffexp"


def _stamp(time_ns: int) -> dict[str, int]:
    sec, nsec = divmod(time_ns, NS_PER_S)
    return {"sec": sec, "nsec": nsec}


def pose_floats(pose: np.ndarray) -> tuple[float, float, float, float, float, float, float]:
    """Translation ``x, y, z`` and unit quaternion ``x, y, z, w`` of a 4x4 pose as floats.

    Written out (Shepperd's method) because ``scipy``'s ``Rotation.from_matrix``
    costs about 0.25 ms a call here, which the per-cycle log cannot afford; on
    the pose's elements as Python floats (the same IEEE operations in the same
    order as on numpy scalars, at a fraction of their cost).
    """
    return rows_floats(pose.tolist())


def rows_floats(m: list[list[float]]) -> tuple[float, float, float, float, float, float, float]:
    """:func:`pose_floats` of a pose given as its rows of floats (``pose.tolist()``)."""
    r0, r1, r2 = m[0], m[1], m[2]
    tr = r0[0] + r1[1] + r2[2]
    if tr > 0.0:
        s = 2.0 * math.sqrt(tr + 1.0)
        q = [(r2[1] - r1[2]) / s, (r0[2] - r2[0]) / s, (r1[0] - r0[1]) / s, 0.25 * s]
    else:
        r = (r0, r1, r2)
        diag = [r0[0], r1[1], r2[2]]
        i = _argmax3(diag)
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(max(1.0 + r[i][i] - r[j][j] - r[k][k], 1e-300))
        q = [0.0, 0.0, 0.0, (r[k][j] - r[j][k]) / s]
        q[i] = 0.25 * s
        q[j] = (r[j][i] + r[i][j]) / s
        q[k] = (r[k][i] + r[i][k]) / s
    return (float(r0[3]), float(r1[3]), float(r2[3]), q[0], q[1], q[2], q[3])


def _argmax3(d: list[float]) -> int:
    """``np.argmax`` of three floats: the first maximum, or the first NaN."""
    for k in range(3):
        if d[k] != d[k]:
            return k
    i = 1 if d[1] > d[0] else 0
    return 2 if d[2] > d[i] else i


def pose_to_transform(pose: np.ndarray) -> tuple[dict[str, float], dict[str, float]]:
    """Translation and unit quaternion (x, y, z, w) of a 4x4 pose (:func:`pose_floats`)."""
    x, y, z, qx, qy, qz, qw = pose_floats(pose)
    return {"x": x, "y": y, "z": z}, {"x": qx, "y": qy, "z": qz, "w": qw}


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
        self._channels: dict[str, int] = {}  # topic: channel id
        self._cids: dict[tuple[str, ...], list[int]] = {}  # a cycle's topics: their channels
        self._records: dict[str, np.ndarray] = {}
        self._names: dict[str, tuple[str, ...]] = {}
        self._layouts: dict[str, struct.Struct] = {}
        self._plans: dict[tuple[str, type], tuple[tuple[str, np.ndarray], ...]] = {}
        self._encoders: dict[str, FieldsEncoder] = {}
        self._encode_fns: dict[str, Callable[[object], bytes]] = {}  # encoder(topic)
        self._row_templates: dict[str, np.ndarray] = {}  # write_rows: an empty record each
        # a subclass that watches write_series sees write_rows' messages there, encoded now
        self._series_watched = type(self).write_series is not Recorder.write_series
        # and one that watches write_batch sees write_cycle's messages there
        self._batch_watched = type(self).write_batch is not Recorder.write_batch
        self._frames: dict[tuple[str, str], str] = {}
        self.message_count = 0
        self.finished = False
        self.taps: list[Callable[[str, int, bytes], None]] = []
        """Called with ``(topic, log_time_ns, message bytes)`` for every message written
        (a live viewer); they must return at once. Empty: no cost."""

    # -- channels -------------------------------------------------------------
    def _channel(self, topic: str) -> int:
        """The channel id of ``topic``, registered on first use."""
        ch = self._channels.get(topic)
        if ch is not None:
            return ch
        if topic in CDR_TOPICS:
            spec = CDR_TOPICS[topic].spec
            sid = self._writer.register_schema(spec.name, "ros2msg", spec.ros2msg.encode())
            cid = self._writer.register_channel(topic, "cdr", sid)
        elif topic in JSON_TOPICS:
            jt = JSON_TOPICS[topic]
            sid = self._writer.register_schema(jt.schema_name, "jsonschema", jt.schema_bytes)
            cid = self._writer.register_channel(topic, "json", sid)
        else:
            raise KeyError(f"unknown topic {topic!r}: add it to ffexp/recording/topics/__init__.py")
        self._channels[topic] = cid
        return int(cid)

    def _series_channel(self, topic: str, times_ns: list[int]) -> int:
        """The channel of a series of ``topic``'s messages at ``times_ns`` (not empty),
        after checking that no time is negative."""
        if min(times_ns) < 0:
            raise ValueError(f"{topic}: negative log time {min(times_ns)} ns")
        ch = self._channels.get(topic)
        return self._channel(topic) if ch is None else ch

    def record(self, topic: str) -> np.ndarray:
        """The preallocated one-element record of a CDR topic (fill, then :meth:`write`)."""
        rec = self._records.get(topic)
        if rec is None:
            rec = CDR_TOPICS[topic].spec.new_record()
            self._records[topic] = rec
        return rec

    def layout(self, topic: str) -> struct.Struct:
        """The ``struct`` layout of a CDR topic's messages: ``layout(topic).pack(CDR_HEADER,
        *values)``, the fields' values flattened in order, gives the same bytes as filling
        :meth:`record` with them (:attr:`MessageSpec.layout
        <ffexp.recording.schema.MessageSpec.layout>`); write them with :meth:`write_bytes`."""
        lay = self._layouts.get(topic)
        if lay is None:
            lay = self._layouts[topic] = CDR_TOPICS[topic].spec.layout
        return lay

    # -- writing --------------------------------------------------------------
    def write_bytes(self, topic: str, time_ns: int, data: bytes) -> None:
        """Write one encoded message.

        Every message's sequence number counts its channel's messages from 0. The
        writer frames messages many cycles at once (:meth:`FastWriter.add_at
        <ffexp.recording.mcap_writer.FastWriter.add_at>`); :meth:`flush` and
        :meth:`finish` write every message given."""
        if time_ns < 0:
            raise ValueError(f"{topic}: negative log time {time_ns} ns")
        ch = self._channels.get(topic)
        if ch is None:
            ch = self._channel(topic)
        self._writer.add_at((ch,), time_ns, (data,))
        self.message_count += 1
        if self.taps:
            for tap in self.taps:
                tap(topic, time_ns, data)
        if self._clock() - self._last_flush >= self._flush_interval_s:
            self.flush()

    def write_batch(self, time_ns: int, messages: list[tuple[str, bytes]]) -> None:
        """Write encoded messages of several topics at one log time, in order (a
        cycle's topics): :meth:`write_bytes` for each, in one call."""
        if messages:
            topics, datas = zip(*messages, strict=True)
            self._write_cycle(time_ns, topics, datas)

    def write_cycle(self, time_ns: int, topics: Sequence[str], datas: Sequence[bytes]) -> None:
        """:meth:`write_batch` of the messages ``datas`` on ``topics`` (one a message).

        A run's cycles that write the same topics in the same order are framed from one
        template (:meth:`FastWriter.add_cycle
        <ffexp.recording.mcap_writer.FastWriter.add_cycle>`). In a subclass that
        overrides :meth:`write_batch`, the messages go through it."""
        if self._batch_watched:
            self.write_batch(time_ns, list(zip(topics, datas, strict=True)))
        else:
            self._write_cycle(time_ns, topics, datas)

    def _write_cycle(self, time_ns: int, topics: Sequence[str], datas: Sequence[bytes]) -> None:
        if not datas:
            return
        if time_ns < 0:
            raise ValueError(f"{topics[0]}: negative log time {time_ns} ns")
        key = tuple(topics)
        cids = self._cids.get(key)
        if cids is None:  # a new mix of topics: their channels, registered in order
            if len(key) != len(datas):
                raise ValueError(f"{len(key)} topics for {len(datas)} messages")
            cids = self._cids[key] = [self._channel(topic) for topic in key]
        elif len(datas) != len(cids):
            raise ValueError(f"{len(key)} topics for {len(datas)} messages")
        self._writer.add_cycle(cids, time_ns, datas)
        self.message_count += len(datas)
        if self.taps:
            for topic, data in zip(topics, datas, strict=True):
                for tap in self.taps:
                    tap(topic, time_ns, data)
        if self._clock() - self._last_flush >= self._flush_interval_s:
            self.flush()

    def write_series(self, topic: str, times_ns: list[int], datas: list[bytes]) -> None:
        """Write encoded messages of one topic at their own log times (e.g. a cycle's
        F/T samples): :meth:`write_bytes` for each, in one call."""
        if not times_ns:
            return
        ch = self._series_channel(topic, times_ns)
        n = len(times_ns)
        self._writer.add_series(ch, times_ns, datas)
        self.message_count += n
        if self.taps:
            for t, data in zip(times_ns, datas, strict=True):
                for tap in self.taps:
                    tap(topic, t, data)
        if self._clock() - self._last_flush >= self._flush_interval_s:
            self.flush()

    def write_rows(self, topic: str, times_ns: list[int], columns: Mapping[str, np.ndarray]
                   ) -> None:
        """Write messages of one CDR topic at their own log times (e.g. a cycle's F/T
        samples) whose fields are given as columns, a row a message (``wrench`` of shape
        ``(n, 6)``, ``seq`` of ``n``, ...; fields not given keep their zeros): the bytes
        of :meth:`record` filled row by row, numpy converting as it does. The writer
        encodes the rows of many cycles at once (:meth:`FastWriter.add_rows
        <ffexp.recording.mcap_writer.FastWriter.add_rows>`); writeable columns are
        copied now. With a tap, or in a subclass that overrides :meth:`write_series`,
        the rows are encoded now and written through :meth:`write_series`."""
        if not times_ns:
            return
        ch = self._series_channel(topic, times_ns)
        template = self._row_templates.get(topic)
        if template is None:  # zeros, the CDR header set
            template = self._row_templates[topic] = CDR_TOPICS[topic].spec.new_record()
        if self.taps or self._series_watched:  # a live viewer, or a subclass watching
            self.write_series(topic, times_ns,  # now
                              encode_rows(template, [columns], len(times_ns)))
            return
        columns = {name: value.copy() if value.flags.writeable else value
                   for name, value in columns.items()}
        self._writer.add_rows(ch, times_ns, template, columns)
        self.message_count += len(times_ns)
        if self._clock() - self._last_flush >= self._flush_interval_s:
            self.flush()

    def write(self, topic: str, time_ns: int) -> None:
        """Write the current contents of :meth:`record` for ``topic``."""
        self.write_bytes(topic, time_ns, self._records[topic].tobytes())

    def write_fields(self, topic: str, time_ns: int, source: object) -> None:
        """Write a CDR topic whose fields are attributes of ``source`` by the same
        names (arrays are flattened row-major, e.g. a 4x4 pose into 16 numbers)."""
        self.write_bytes(topic, time_ns, self.encode_fields(topic, source))

    def encode_fields(self, topic: str, source: object) -> bytes:
        """The message of :meth:`write_fields`, not written.

        Encoded by the topic's :class:`~ffexp.recording.encode.FieldsEncoder` when
        every value is plainly of its field's type; anything else (a value numpy
        would convert, e.g. a float into an integer field) fills the numpy record.
        """
        enc = self._encoders.get(topic)
        if enc is None:
            enc = self._encoders[topic] = FieldsEncoder(CDR_TOPICS[topic].spec)
        data = enc.encode(source)
        return self._encode_fields_numpy(topic, source) if data is None else data

    def encoder(self, topic: str) -> Callable[[object], bytes]:
        """:meth:`encode_fields` of ``topic`` as one function of the source (the same
        bytes; the numpy record filled where the values ask for it), for a caller that
        encodes the topic every cycle."""
        fn = self._encode_fns.get(topic)
        if fn is None:
            enc = self._encoders.get(topic)
            if enc is None:
                enc = self._encoders[topic] = FieldsEncoder(CDR_TOPICS[topic].spec)
            fn = self._encode_fns[topic] = enc.with_fallback(
                lambda source: self._encode_fields_numpy(topic, source))
        return fn

    def _encode_fields_numpy(self, topic: str, source: object) -> bytes:
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
        return rec.tobytes()

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
        """Write many messages of one CDR topic (e.g. all F/T samples of a cycle): the
        rows of ``records`` (numpy records of the topic's layout, their bytes the
        messages) at ``times_ns``, framed for the file in one go
        (:meth:`FastWriter.add_fixed <ffexp.recording.mcap_writer.FastWriter.add_fixed>`)."""
        n = len(times_ns)
        if not n:
            return
        times = np.asarray(times_ns, dtype=np.int64)
        if int(times.min()) < 0:
            raise ValueError(f"{topic}: negative log time {int(times.min())} ns")
        ch = self._channels.get(topic)
        if ch is None:
            ch = self._channel(topic)
        self._writer.add_fixed(ch, times, self._writer.reserve(ch, n), records)
        self.message_count += n
        if self.taps:
            blob, size = records.tobytes(), records.dtype.itemsize
            for i, t in enumerate(times.tolist()):
                msg = blob[i * size:(i + 1) * size]
                for tap in self.taps:
                    tap(topic, t, msg)
        if self._clock() - self._last_flush >= self._flush_interval_s:
            self.flush()

    def write_json(self, topic: str, time_ns: int, message: Mapping[str, Any]) -> None:
        """Write one JSON message on a low-rate topic."""
        self.write_bytes(topic, time_ns, self.encode_json(message))

    @staticmethod
    def encode_json(message: Mapping[str, Any]) -> bytes:
        """The bytes :meth:`write_json` writes, not written (for :meth:`write_batch`)."""
        return json.dumps(message, separators=(",", ":")).encode()

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
        self.transform_rows(time_ns, parent, child, pose.tolist())

    def transform_rows(self, time_ns: int, parent: str, child: str,
                       rows: list[list[float]]) -> None:
        """:meth:`transform` of a pose given as its rows of floats (``pose.tolist()``)."""
        self.write_bytes("/tf", time_ns, self.encode_transform(time_ns, parent, child, rows))

    def encode_transform(self, time_ns: int, parent: str, child: str,
                         rows: list[list[float]]) -> bytes:
        """The ``/tf`` message of :meth:`transform_rows`, not written (for
        :meth:`write_batch`)."""
        v = rows_floats(rows)
        isfinite = math.isfinite
        if not (isfinite(v[0]) and isfinite(v[1]) and isfinite(v[2]) and isfinite(v[3])
                and isfinite(v[4]) and isfinite(v[5]) and isfinite(v[6])):
            raise ValueError(f"/tf: {child} pose is not finite")
        frames = self._frames.get((parent, child))
        if frames is None:
            frames = self._frames[(parent, child)] = (
                f'"parent_frame_id":{json.dumps(parent)},"child_frame_id":{json.dumps(child)},')
        sec, nsec = divmod(time_ns, NS_PER_S)
        text = (
            f'{{"timestamp":{{"sec":{sec},"nsec":{nsec}}},{frames}'
            f'"translation":{{"x":{v[0]!r},"y":{v[1]!r},"z":{v[2]!r}}},'
            f'"rotation":{{"x":{v[3]!r},"y":{v[4]!r},"z":{v[5]!r},"w":{v[6]!r}}}}}'
        )
        return text.encode()

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
        self._writer.flush()
        self._fh.flush()
        self._last_flush = self._clock()

    def finish(self) -> None:
        """Write the summary and close the file; idempotent."""
        if self.finished:
            return
        self.finished = True
        try:
            self._writer.finish()
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
