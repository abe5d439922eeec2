"""What one run writes to its recording, and nothing else: the loop's only I/O sink.

Per cycle, in log-time order (log time = the run's UTC start + run time):
every F/T sample of the cycle (``/ft/raw``, :meth:`RunLog.samples`, each at
its own time, which precedes the cycle's), the cycle's events and phase
changes, then at the cycle's time the robot state's back-end extras on the
topics they name (FRI: ``/robot/measurement``, ``/robot/link``), the estimate
(``/estimator/state``), the control terms (``/control/terms``, plus the
method's own topic if it declares one), the runner's intent beside what the
driver really applied (``/control/command``; the back-end's own form, e.g.
``/robot/command``), ground truth when the robot has it (the topics it names:
``/sim/truth``, ``/sim/body/<name>``, ...; the frames fixed on a body once, on
``/sim/attached``), the scenario's own measures (``/task/funnel``), every new tracker
observation (``/target/pose``, and ``/tf`` frame ``target_tracked``) and,
every ``tf_period_s``, ``/tf``. Verdict notes of the task go to
``/alignment/verdict``.

A lean run log (``lean=True``: a study's runs, ``ffexp run --lean``) keeps only the
topics the metrics read (:func:`ffexp.recording.batch.lean_topic`: the estimate, the
control terms, the robot state, the back-end's link topics, the truth, the scenario's
measures, the tracker's ``/target/pose`` and the JSON notes) and builds no message of
the others: no ``/ft/raw``, ``/control/command``, method topic, back-end wire topics
(``/robot/measurement``, ``/robot/command``), ``/tf``, nor its sinks' (the 3-D
scene). The file says so in its ``recording`` metadata
(:func:`~ffexp.recording.batch.lean_metadata`); a full run log writes none.

Without a :class:`~ffexp.recording.Recorder` (tests, benchmarks) only the
events are kept, in :attr:`RunLog.events`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any, Protocol

import numpy as np

from drivers.base.types import (
    F64,
    NS_PER_S,
    AppliedCommand,
    CartesianCommand,
    Extras,
    FtSamples,
    GroundTruth,
    RobotState,
    TargetObservation,
)
from ffexp.contracts import Phase, StopReason
from ffexp.controllers import Controller
from ffexp.estimation import Estimate
from ffexp.recording import Recorder
from ffexp.recording.batch import RECORDING_METADATA, TopicFilter, lean_metadata
from ffexp.recording.cycle import (
    command_message,
    estimator_message,
    state_message,
    terms_message,
)
from ffexp.recording.topics.target import TRACKED_FRAME
from ffexp.scenarios.base import Scenario
from ffexp.task import Event, Note, PhaseChange, Verdict


class CycleSink(Protocol):
    """Something that writes its own topics once per cycle beside the run log's
    (the 3-D scene of the rig); it decides its own rate."""

    def cycle(self, log_ns: int, state: RobotState, target: TargetObservation | None,
              out: list[tuple[str, bytes]] | None = None) -> None:
        """One cycle at log time ``log_ns``; its messages appended to ``out`` (the
        run log's batch of the cycle, written after) when given, else written."""


class _Kept(dict[str, bool]):
    """Per topic, whether a run log writes it (its filter asked once per topic)."""

    def __init__(self, keeps: Callable[[str], bool]) -> None:
        super().__init__()
        self._keeps = keeps

    def __missing__(self, topic: str) -> bool:
        kept = self[topic] = self._keeps(topic)
        return kept


class _Encoders(dict[str, Callable[[object], bytes] | None]):
    """Per topic, the recorder's encoder of its fields (:meth:`Recorder.encoder
    <ffexp.recording.Recorder.encoder>`), or ``None`` when the log does not keep the
    topic: one lookup a message, each topic's decided once."""

    def __init__(self, recorder: Recorder, kept: _Kept) -> None:
        super().__init__()
        self._recorder = recorder
        self._kept = kept
        # per tuple of topics an extras names: its kept topics and their encoders
        self._extras: dict[tuple[str, ...], tuple[tuple[str, Callable[[object], bytes]], ...]] = {}
        # per shape of a plain ground truth (prefix, bodies, sites, attached frames): its
        # kept topics (the truth's, or None; the bodies' in order), or None when a site is
        # not attached (its messages then asked for)
        self._truths: dict[tuple[object, ...], tuple[
            tuple[str, Callable[[object], bytes]] | None,
            tuple[tuple[str, Callable[[object], bytes]] | None, ...]] | None] = {}
        self._truth: tuple[Any, ...] | None = None  # the last truth's shape and plan

    def __missing__(self, topic: str) -> Callable[[object], bytes] | None:
        fn = self[topic] = self._recorder.encoder(topic) if self._kept[topic] else None
        return fn

    def _pairs(self, topics: Iterable[str]) -> tuple[tuple[str, Callable[[object], bytes]], ...]:
        return tuple((topic, fn) for topic in topics if (fn := self[topic]) is not None)

    def extras_into(self, extras: Extras, topics: list[str], datas: list[bytes]) -> None:
        """A back-end's extras' kept topics and their messages appended to the cycle's."""
        names = extras.topics()
        plan = self._extras.get(names)
        if plan is None:
            plan = self._extras[names] = self._pairs(names)
        for topic, fn in plan:
            topics.append(topic)
            datas.append(fn(extras))

    def truth_into(self, truth: GroundTruth, topics: list[str], datas: list[bytes]) -> None:
        """The kept messages of the truth (:meth:`GroundTruth.messages
        <drivers.base.types.GroundTruth.messages>`) appended to the cycle's; a plain
        ``GroundTruth``'s topics worked out once for its prefix, bodies and frames (the
        last ones compared by their names: the bodies in order, the frames and the
        attached ones as sets, a frame not attached making the plan ``None``)."""
        plan = None
        if type(truth) is GroundTruth:
            last = self._truth
            if (last is not None and truth.topic_prefix == last[0]
                    and tuple(truth.bodies) == last[1] and truth.sites.keys() == last[2]
                    and truth.attached.keys() == last[3]):
                plan = last[4]
            else:
                key = (truth.topic_prefix, *truth.bodies, None, *truth.sites, None,
                       *truth.attached)
                if key in self._truths:
                    plan = self._truths[key]
                else:
                    plan = self._truths[key] = self._truth_plan(truth)
                self._truth = (truth.topic_prefix, tuple(truth.bodies), set(truth.sites),
                               set(truth.attached), plan)
        if plan is None:
            for topic, source in truth.messages():
                fn = self[topic]
                if fn is not None:
                    topics.append(topic)
                    datas.append(fn(source))
            return
        own, bodies = plan
        if own is not None:
            topics.append(own[0])
            datas.append(own[1](truth))
        for entry, body in zip(bodies, truth.bodies.values()):  # noqa: B905  # one length
            if entry is not None:
                topics.append(entry[0])
                datas.append(entry[1](body))

    def _truth_plan(self, truth: GroundTruth) -> tuple[
            tuple[str, Callable[[object], bytes]] | None,
            tuple[tuple[str, Callable[[object], bytes]] | None, ...]] | None:
        messages = truth.messages()
        bodies = list(truth.bodies.values())
        if (len(messages) != 1 + len(bodies) or messages[0][1] is not truth
                or not all(m[1] is b for m, b in zip(messages[1:], bodies, strict=True))):
            return None  # a site not attached, or messages of another order
        own = self[messages[0][0]]
        return (None if own is None else (messages[0][0], own),
                tuple(None if (fn := self[topic]) is None else (topic, fn)
                      for topic, _ in messages[1:]))


class RunLog:
    """Writes a run's cycles and notes through a recorder (or only keeps the events).

    Args:
        recorder: the open recording, or ``None``.
        start_utc_ns: log-time origin (run start in UTC).
        tf_period_s: period of ``/tf``.
        lean: keep only the topics the metrics read (the module's doc).
        truth_prefix: the ground truth's topic prefix a lean log keeps.
    """

    def __init__(self, recorder: Recorder | None, start_utc_ns: int, tf_period_s: float, *,
                 lean: bool = False, truth_prefix: str = GroundTruth.topic_prefix) -> None:
        self.rec = recorder
        self.lean = lean
        """Only the topics the metrics read are built and written."""
        self.truth_prefix = truth_prefix
        self._filter = TopicFilter(lean, truth_prefix)
        self._kept = _Kept(self._filter.keeps)  # what keeps() says, a dict lookup a topic
        self._enc = None if recorder is None else _Encoders(recorder, self._kept)
        if recorder is not None and lean:
            recorder.metadata(RECORDING_METADATA, lean_metadata(True, truth_prefix))
        self.start_utc_ns = start_utc_ns
        self.tf_period_ns = round(tf_period_s * NS_PER_S)
        self.events: list[tuple[float, str, str]] = []
        """``(run time [s], name, message)`` of every event, for the outcome."""
        self._next_tf_ns = 0
        self.verdicts: list[Verdict] = []
        """Every verdict note, in order (the last one with ``final`` is the run's)."""
        self._target_frames = -1
        self._target_valid = False
        self.sinks: list[CycleSink] = []
        """Further per-cycle writers (set up by :mod:`ffexp.experiment`)."""
        self.cycles = 0
        """Cycles written so far."""
        self._attached: object = None  # the truth's attached frames last written

    def keeps(self, topic: str) -> bool:
        """Whether this log writes ``topic`` (all of them unless :attr:`lean`)."""
        return self._filter.keeps(topic)

    def note(self, t_ns: int, note: Note) -> None:
        """An event, or a phase change (``/runner/phase`` and an event)."""
        if isinstance(note, Event):
            self.event(t_ns, note.level, note.name, note.message)
            return
        if isinstance(note, Verdict):
            self.verdict(t_ns, note)
            return
        self.phase(t_ns, note)

    def verdict(self, t_ns: int, v: Verdict) -> None:
        """Who judges, or the run's verdict, on ``/alignment/verdict``."""
        self.verdicts.append(v)
        if self.rec is not None:
            evidence = {k: float(x) for k, x in v.evidence.items() if np.isfinite(x)}
            self.rec.write_json("/alignment/verdict", self.start_utc_ns + t_ns, {
                "label": v.label, "source": v.source, "reason": v.reason, "truth": v.truth,
                "final": v.final, "evidence": evidence})

    def event(self, t_ns: int, level: str, name: str, message: str) -> None:
        self.events.append((t_ns / NS_PER_S, name, message))
        if self.rec is not None:
            self.rec.log(self.start_utc_ns + t_ns, level, name, message)

    def phase(self, t_ns: int, change: PhaseChange, *, announce: bool = True) -> None:
        stop = change.stop
        if self.rec is not None:
            self.rec.write_json(
                "/runner/phase",
                self.start_utc_ns + t_ns,
                {
                    "phase": change.new.name,
                    "phase_id": int(change.new),
                    "reason": change.reason,
                    "stop_reason": stop.value if stop is not None else "",
                    "aligned": stop is StopReason.ALIGNED,
                },
            )
        if announce:
            level = "ERROR" if change.new == Phase.ABORT else "INFO"
            self.event(t_ns, level, "phase", f"{change.old.name} -> {change.new.name}: "
                       f"{change.reason}")

    def samples(self, t0_ns: int, ft: FtSamples) -> None:
        """Every F/T sample of a cycle on ``/ft/raw`` at its own time (robot clock
        minus ``t0_ns``, the run's start): call it before the cycle's notes and
        :meth:`cycle`, so the recording stays in log-time order."""
        rec = self.rec
        if self.lean or rec is None or not len(ft):  # a lean log keeps no F/T sample
            return
        times = (ft.time_ns + (self.start_utc_ns - t0_ns)).tolist()
        # the numpy record filled row by row (seq modulo 2^32: numpy's cast into uint32),
        # encoded with the samples of many cycles at once
        rec.write_rows("/ft/raw", times, {"wrench": ft.wrench, "seq": ft.seq,
                                          "status": ft.status})

    def cycle(
        self,
        t_ns: int,
        t0_ns: int,
        state: RobotState,
        ft: FtSamples,
        est: Estimate,
        phase: Phase,
        controller: Controller,
        approach_wrench: F64 | None,
        setpoint: F64,
        total: F64,
        intent: CartesianCommand | None,
        applied: AppliedCommand,
        target: TargetObservation | None = None,
        scenario: Scenario | None = None,
    ) -> None:
        """Everything of one cycle but its F/T samples (:meth:`samples`).
        ``approach_wrench`` is the approach law's output when it acted this
        cycle; the controller's terms are recorded in ALIGN. ``t0_ns``, the
        robot time of the run's start, is not used here (kept for callers)."""
        self.cycles += 1
        rec = self.rec
        if rec is None:
            return
        log_ns = self.start_utc_ns + t_ns
        # the cycle's messages in order: their topics, their bytes (each built only when
        # its topic is kept)
        kept, enc = self._kept, self._enc
        assert enc is not None
        topics = ["/robot/state"]
        datas = [state_message(state)]
        if state.extras is not None:
            enc.extras_into(state.extras, topics, datas)
        topics.append("/estimator/state")
        datas.append(estimator_message(est.wrench, est.wrench_std, est.bias, est.twist_tcf,
                                       est.f_z, len(ft), est.in_contact))
        align = phase == Phase.ALIGN
        topics.append("/control/terms")
        datas.append(terms_message(controller.terms if align else None, approach_wrench,
                                   total, controller.f_ref, setpoint, int(phase)))
        if align and controller.topic is not None:
            topic = controller.topic.topic
            fn = enc[topic]
            if fn is not None:
                topics.append(topic)
                datas.append(fn(controller.extra))

        if kept["/control/command"]:
            topics.append("/control/command")
            datas.append(command_message(intent, applied))
        if applied.extras is not None:
            enc.extras_into(applied.extras, topics, datas)
        truth = state.truth
        if truth is not None:
            if truth.attached is not self._attached:  # once a run: frames fixed on a body
                self._attached = truth.attached
                fixed = truth.attached_message()
                if fixed is not None and kept[fixed[0]]:
                    topics.append(fixed[0])
                    datas.append(rec.encode_json(fixed[1]))
            enc.truth_into(truth, topics, datas)
        if scenario is not None:
            for topic, source in scenario.messages():
                fn = enc[topic]
                if fn is not None:
                    topics.append(topic)
                    datas.append(fn(source))
        new_target = target is not None and (target.frames != self._target_frames
                                             or target.valid != self._target_valid)
        if self.lean:
            if new_target:
                assert target is not None
                self._target(log_ns, state, target, topics, datas)
            rec.write_cycle(log_ns, topics, datas)  # no /tf, no sink: the metrics read neither
            return
        if t_ns >= self._next_tf_ns:
            self._next_tf_ns = t_ns + self.tf_period_ns
            topics.append("/tf")
            datas.append(rec.encode_transform(log_ns, "base", "tool", state.tcp_pose_m.tolist()))
            if truth is not None:
                self._truth_tf(log_ns, truth, topics, datas)
        if new_target:
            assert target is not None
            self._target(log_ns, state, target, topics, datas)
        if self.sinks:
            msgs: list[tuple[str, bytes]] = []
            for sink in self.sinks:
                sink.cycle(log_ns, state, target, msgs)
            for topic, data in msgs:
                topics.append(topic)
                datas.append(data)
        rec.write_cycle(log_ns, topics, datas)  # the cycle's one write

    def _truth_tf(self, log_ns: int, truth: GroundTruth, topics: list[str],
                  datas: list[bytes]) -> None:
        """``/tf`` of the truth's bodies in the robot's base frame (and, on a floating
        base, the world in it)."""
        assert self.rec is not None
        inv = None if truth.base_pose is None else np.linalg.inv(truth.base_pose)
        if inv is not None:
            topics.append("/tf")
            datas.append(self.rec.encode_transform(log_ns, "base", "world", inv.tolist()))
        for name, body in truth.bodies.items():
            pose = body.pose if inv is None else inv @ body.pose
            topics.append("/tf")
            datas.append(self.rec.encode_transform(log_ns, "base", name, pose.tolist()))

    def _target(self, log_ns: int, state: RobotState, target: TargetObservation,
                topics: list[str], datas: list[bytes]) -> None:
        """A new tracker observation: ``/target/pose`` and, when valid, ``/tf``."""
        assert self.rec is not None
        self._target_frames, self._target_valid = target.frames, target.valid
        r = self.rec.record("/target/pose")
        r["time_ns"] = target.time_ns
        r["pose"] = target.pose_m.reshape(-1)
        r["mouth"] = target.mouth_m.reshape(-1)
        r["valid"] = int(target.valid)
        r["frames"] = target.frames & 0xFFFFFFFF
        r["age_s"] = (state.time_ns - target.time_ns) / NS_PER_S
        topics.append("/target/pose")
        datas.append(r.tobytes())
        if target.valid and not self.lean:
            topics.append("/tf")
            datas.append(self.rec.encode_transform(log_ns, "base", TRACKED_FRAME,
                                                   target.pose_m.tolist()))
