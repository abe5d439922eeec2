"""Recordings of a batch of runs: each run its own MCAP file, the batch encoded at once.

A batch of ``N`` runs that step together writes, per cycle, the same fixed-layout
CDR topics for every run. :class:`BatchEncoder` holds one topic's messages for the
whole batch as ``N`` numpy records of the topic's layout (the run axis first): a
field is filled for every run with one assignment from an array whose first axis
is the run, the ``N`` messages are cut from one ``tobytes``. A run's message is
byte for byte the one :meth:`Recorder.encode_fields
<ffexp.recording.Recorder.encode_fields>` makes of the same values alone
(``tests/test_recording_batch.py``).

:class:`BatchRecorder` writes a batch's cycle: each run's messages into that run's
own :class:`~ffexp.recording.Recorder`, in the order given, as one
:meth:`~ffexp.recording.Recorder.write_batch` of that run (the same messages, in the
same order, as the run made alone). A run that leaves the batch (aligned, aborted,
failed) is finished alone (:meth:`BatchRecorder.finish_run`); the others go on.

A study may ask for lean recordings: only :func:`lean_topics` (what the metrics,
the outcome and the tables read) and the ground truth's topics are written, and
every file says so in its ``recording`` metadata (``lean``, ``topics``:
:func:`lean_metadata`). A single run records lean the same way
(:class:`ffexp.runlog.RunLog` with ``lean``; ``ffexp run --lean``, ``ffexp sweep
--lean``). A file without that metadata is a full recording.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from functools import cache
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ffexp.recording.recorder import Recorder
from ffexp.recording.schema import CDR_HEADER
from ffexp.recording.topics import CDR_TOPICS

__all__ = ["LEAN_TOPICS", "RECORDING_METADATA", "BatchEncoder", "BatchRecorder", "TopicFilter",
           "is_lean", "lean_metadata", "lean_topic", "lean_topics", "missing_topic"]

#: The metadata record that says what a recording keeps (``lean``, ``topics``).
RECORDING_METADATA = "recording"

#: The topics a lean recording keeps: the per-cycle series of
#: :func:`ffexp.analysis.series`, the robot's state and the scenario's measures, beside
#: the low-rate JSON topics (events, phases, verdicts, tracker observations). A lean
#: recording also keeps the back-ends' link topics (:func:`lean_topics`) and the ground
#: truth's topics, whichever back-end writes them (the topics under its
#: ``GroundTruth.topic_prefix``). Left out: the F/T samples, the back-end's wire
#: messages (``/robot/measurement``, ``/robot/command``), the commands
#: (``/control/command``, a method's own topic), ``/tf`` and the 3-D scene.
LEAN_TOPICS: frozenset[str] = frozenset({
    "/estimator/state", "/control/terms", "/robot/state", "/task/funnel", "/events",
    "/runner/phase", "/alignment/verdict", "/target/pose",
})


def lean_topics() -> frozenset[str]:
    """Every topic a lean recording keeps but the truth's: :data:`LEAN_TOPICS`, the
    back-ends' link topics the metrics read (the link statistics of
    :func:`drivers.registry.link_stats`, the link-fault counters of
    :func:`ffexp.linkcheck.fault_topics`: FRI ``/robot/link``, a UR's ``/robot/ur``,
    ...), so that a lean run's metrics are the full run's, and every registered
    scenario's own measures (:func:`ffexp.scenarios.scenario_topics`: ``/task/funnel``,
    ``/task/docking6``)."""
    from drivers import registry
    from ffexp.scenarios import scenario_topics

    links = {s.topic for s in registry.link_stats()} | {c.topic for c in registry.link_faults()}
    return LEAN_TOPICS | frozenset(links) | _task_topics(scenario_topics())


@cache
def _task_topics(topics: tuple[Any, ...]) -> frozenset[str]:
    return frozenset(t.topic for t in topics)


def lean_topic(topic: str, truth_prefix: str | None = None) -> bool:
    """Whether a lean recording keeps ``topic`` (:func:`lean_topics`, and the ground
    truth's topics under ``truth_prefix`` when the runs have a truth)."""
    return topic in lean_topics() or (truth_prefix is not None
                                      and topic.startswith(truth_prefix.rstrip("/") + "/"))


class TopicFilter:
    """Which topics a recording writes: all of them, or a lean recording's
    (:func:`lean_topic`, decided once per topic)."""

    def __init__(self, lean: bool, truth_prefix: str | None = None) -> None:
        self.lean = lean
        self.truth_prefix = truth_prefix
        self._kept: dict[str, bool] = {}

    def keeps(self, topic: str) -> bool:
        """Whether ``topic`` is written."""
        if not self.lean:
            return True
        kept = self._kept.get(topic)
        if kept is None:
            kept = self._kept[topic] = lean_topic(topic, self.truth_prefix)
        return kept


def lean_metadata(lean: bool, truth_prefix: str | None = None) -> dict[str, str]:
    """The ``recording`` metadata of a file: ``lean`` (``true``/``false``) and ``topics``
    (what it keeps, comma-separated: ``*`` for all, ``<prefix>/*`` for the truth's)."""
    if not lean:
        return {"lean": "false", "topics": "*"}
    kept = sorted(lean_topics())
    if truth_prefix:
        kept.append(f"{truth_prefix.rstrip('/')}/*")
    return {"lean": "true", "topics": ",".join(kept)}


def is_lean(metadata: Mapping[str, Mapping[str, str]]) -> bool:
    """Whether a recording's metadata (``Recording.metadata``) says it is lean."""
    return metadata.get(RECORDING_METADATA, {}).get("lean") == "true"


def missing_topic(path: object, metadata: Mapping[str, Mapping[str, str]],
                  topics: Iterable[str], needed: Iterable[str]) -> str | None:
    """Why a recording cannot give what a command needs: for a lean recording (its
    ``metadata``) that lacks one of ``needed`` (its ``topics`` are those it has), one
    line naming the file and the topic; ``None`` when it has them all or is full (a
    full file without a topic never had it: the command's own rules apply)."""
    if not is_lean(metadata):
        return None
    have = set(topics)
    for topic in needed:
        if topic not in have:
            return (f"{path}: a lean recording (the topics the metrics read): it has no "
                    f"{topic} (run it again recording full: without --lean, or with --full)")
    return None


class BatchEncoder:
    """One CDR topic's messages for ``runs`` runs, filled field by field for all of them.

    Args:
        topic: a CDR topic (or a member of a topic family).
        runs: the batch size ``N``.
    """

    def __init__(self, topic: str, runs: int) -> None:
        if runs < 1:
            raise ValueError(f"{topic}: a batch needs at least one run, not {runs}")
        self.topic = topic
        self.spec = CDR_TOPICS[topic].spec
        self.runs = runs
        self.records = np.zeros(runs, dtype=self.spec.dtype)
        self.records["_cdr_header"] = np.frombuffer(CDR_HEADER, dtype="V4")[0]
        self.size = self.spec.dtype.itemsize
        self._names = tuple(f.name for f in self.spec.fields)
        self._counts = {f.name: f.count for f in self.spec.fields}

    def set(self, name: str, values: ArrayLike) -> None:
        """Field ``name`` of every run: ``values`` with the run axis first (``(N,)`` for a
        scalar field, ``(N, ...)`` for an array field: its elements row-major, a 4x4
        pose as its 16 numbers); one value for all runs broadcasts."""
        count = self._counts.get(name)
        if count is None:
            raise KeyError(f"{self.topic}: no field {name!r}")
        arr = np.asarray(values)
        if count > 1 and arr.ndim >= 2 and arr.shape[0] == self.runs:
            arr = arr.reshape(self.runs, count)
        self.records[name] = arr

    def fill(self, fields: Mapping[str, ArrayLike]) -> None:
        """:meth:`set` for several fields."""
        for name, values in fields.items():
            self.set(name, values)

    def fill_from(self, sources: Sequence[object]) -> None:
        """Every field from ``N`` objects with same-named attributes (one per run, as
        :meth:`Recorder.encode_fields <ffexp.recording.Recorder.encode_fields>` takes
        one): per field, the runs' values stacked and assigned at once."""
        if len(sources) != self.runs:
            raise ValueError(f"{self.topic}: {len(sources)} sources for {self.runs} runs")
        for name in self._names:
            values = [getattr(s, name) for s in sources]
            if self._counts[name] > 1:
                self.records[name] = np.stack([np.asarray(v).reshape(-1) for v in values])
            else:
                self.records[name] = values

    def messages(self) -> list[bytes]:
        """The ``N`` messages, the run's index in the batch first to last."""
        blob, size = self.records.tobytes(), self.size
        return [blob[i * size:(i + 1) * size] for i in range(self.runs)]


class BatchRecorder:
    """The recordings of a batch's runs, one :class:`Recorder` each.

    Args:
        recorders: each run's open recording, in the batch's run order.
        lean: write only :func:`lean_topics` and the truth's topics (said in each
            file's ``recording`` metadata).
        truth_prefix: the ground truth's topic prefix (``GroundTruth.topic_prefix``)
            when the runs have a truth.
    """

    def __init__(self, recorders: Sequence[Recorder], *, lean: bool = False,
                 truth_prefix: str | None = None) -> None:
        self.recorders: list[Recorder | None] = list(recorders)
        self.lean = lean
        self.truth_prefix = truth_prefix
        self._filter = TopicFilter(lean, truth_prefix)
        for rec in recorders:
            rec.metadata(RECORDING_METADATA, lean_metadata(lean, truth_prefix))

    @property
    def runs(self) -> int:
        return len(self.recorders)

    @property
    def active(self) -> list[int]:
        """The runs still in the batch (not finished)."""
        return [i for i, rec in enumerate(self.recorders) if rec is not None]

    def keeps(self, topic: str) -> bool:
        """Whether this batch's recordings write ``topic``."""
        return self._filter.keeps(topic)

    def encoder(self, topic: str) -> BatchEncoder:
        """A new :class:`BatchEncoder` of ``topic`` for this batch's runs."""
        return BatchEncoder(topic, self.runs)

    def cycle(self, log_ns: Sequence[int],
              topics: Iterable[tuple[str, BatchEncoder | Sequence[bytes | None]]]) -> None:
        """One cycle of every run still in the batch, at its own log time ``log_ns[i]``.

        ``topics`` in the order a run writes them: per topic a :class:`BatchEncoder`
        (every run has the message) or ``N`` messages already encoded (``None``: that
        run has none this cycle). Each run gets its messages in one write.
        """
        per_run: list[list[tuple[str, bytes]]] = [[] for _ in self.recorders]
        for topic, source in topics:
            if not self.keeps(topic):
                continue
            datas: Sequence[bytes | None] = (source.messages() if isinstance(source, BatchEncoder)
                                             else source)
            if len(datas) != self.runs:
                raise ValueError(f"{topic}: {len(datas)} messages for {self.runs} runs")
            for msgs, data in zip(per_run, datas, strict=True):
                if data is not None:
                    msgs.append((topic, data))
        for rec, t, msgs in zip(self.recorders, log_ns, per_run, strict=True):
            if rec is not None and msgs:
                rec.write_batch(t, msgs)

    def write_json(self, run: int, topic: str, time_ns: int, message: Mapping[str, Any]) -> None:
        """A JSON message of one run (events, phases, verdicts: low rate, per run)."""
        rec = self.recorders[run]
        if rec is not None and self.keeps(topic):
            rec.write_json(topic, time_ns, message)

    def finish_run(self, run: int) -> None:
        """Finish run ``run``'s recording now (it left the batch); the others go on."""
        rec = self.recorders[run]
        if rec is not None:
            self.recorders[run] = None
            rec.finish()

    def finish(self) -> None:
        """Finish every recording still open (each even if another fails)."""
        errors: list[BaseException] = []
        for i in self.active:
            try:
                self.finish_run(i)
            except Exception as exc:
                errors.append(exc)
        if errors:
            raise errors[0]
