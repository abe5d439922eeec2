"""Replay a recording, open loop, through the pure parts of a (changed) protocol.

The recording holds what every cycle of the loop was fed: ``/robot/state`` (the
robot-neutral state), the F/T samples on ``/ft/raw``, the simulator's truth on
``/sim/truth`` and the tracker's observations on ``/target/pose``. :func:`replay`
rebuilds those inputs cycle by cycle and feeds them through
:class:`ffexp.loop.Cycle` (estimator, safety checks, task, approach law and the
method's controller) of the given protocol, writing what it would have commanded
and why (estimate, control terms, command, events, phases) to a new recording
through :class:`~ffexp.runlog.RunLog`, as a run does.

Open loop: the recorded measurements are the answer of the real (or simulated)
world to the *recorded* commands. The replay is therefore what the changed
controller would have commanded on exactly this data, and it is the answer to
"what would it have done" only until its commands differ from the recorded
ones; from then on the world would have moved differently. :func:`replay`
compares every cycle's command with the recorded ``/control/command`` and
reports the first cycle where they differ (:class:`Divergence`), and says so
in the output recording (an event and the ``replay`` metadata).

How the inputs are rebuilt:

- the F/T samples of a cycle are the recorded ones in log-time order, as many
  as that cycle's ``/estimator/state.n_samples`` says the loop got (exact:
  a sample stamped at a cycle's own time may reach the loop only in the next
  cycle); without ``/estimator/state`` the samples with log time after the
  previous cycle's and up to this cycle's;
- ground truth is the ``/sim/truth`` message of the cycle's log time, when the
  recording has one;
- the target observation is the newest ``/target/pose`` at or before the
  cycle's log time (the run log writes each new observation at the cycle it
  was first seen), none before the first;
- what the robot "applied" is the replay's own intent (the replay has no robot),
  with the status flags the robot reported in that cycle; a cycle without an
  intent (the robot keeps its own set-point) records the applied command of the
  recording;
- back-end extras (FRI packets, the driver's link events) are not replayed.
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drivers.base.types import (
    NS_PER_S,
    AppliedCommand,
    ApplyStatus,
    BodyTruth,
    CartesianCommand,
    FtSamples,
    GroundTruth,
    LinkHealth,
    RobotState,
    TargetObservation,
)
from ffexp.contracts import Phase, Stop, StopReason
from ffexp.diff import within
from ffexp.errors import InputError
from ffexp.loop import Cycle
from ffexp.protocol import RunProtocol, load_run_protocol, run_protocol_from
from ffexp.recording import Recorder, Recording, TopicData, load
from ffexp.recording.batch import missing_topic
from ffexp.recording.reader import contents

#: The tolerance of "the same command": float rounding, not a physical threshold.
RTOL = 1e-9
ATOL = 1e-9
#: The intent fields of ``/control/command`` compared cycle by cycle.
COMMAND_FIELDS = ("given", "pose", "stiffness", "damping", "wrench")
#: What the replay needs of a recording (and reads, nothing else).
TRUTH_PREFIX = GroundTruth().topic_prefix
INPUT_TOPICS = ("/robot/state", "/ft/raw", "/estimator/state", f"{TRUTH_PREFIX}/truth",
                "/target/pose", "/control/command")
#: The truth's topics of each body and named frame (one per name: their prefixes).
TRUTH_PART_PREFIXES = (f"{TRUTH_PREFIX}/body/", f"{TRUTH_PREFIX}/site/")

OPEN_LOOP = (
    "open-loop replay: the recorded measurements answer the recorded commands, so the replay "
    "says what the controller would have commanded only until its commands differ from the "
    "recorded ones"
)


@dataclass(frozen=True)
class Divergence:
    """The first cycle whose command differs from the recorded one."""

    t_s: float
    """Run time of that cycle [s]."""
    cycle: int
    topic: str
    field: str
    """The first differing column, e.g. ``wrench_1`` (element 1 of ``wrench``)."""
    recorded: float
    replayed: float

    def line(self) -> str:
        return (f"commands differ from the recorded ones from t = {self.t_s:.3f} s (cycle "
                f"{self.cycle}) on {self.topic} {self.field}: recorded {self.recorded:.6g}, "
                f"replayed {self.replayed:.6g}; open-loop replay is not valid after it")


@dataclass(frozen=True)
class ReplayResult:
    """What :func:`replay` did."""

    path: Path
    cycles: int
    recorded_cycles: int
    divergence: Divergence | None
    diverging_cycles: int
    """Cycles whose command differs from the recorded one (beyond :data:`RTOL`, :data:`ATOL`)."""
    max_command_diff: float
    """Largest absolute difference of any command field over all compared cycles."""
    phase: Phase
    stop_reason: StopReason | None
    stop_message: str
    end_s: float
    warnings: list[str]
    """The reader's warnings on the recording (an unfinished file)."""

    @property
    def ended(self) -> str:
        """How the replayed task ended: ``DONE (aligned) at 8.77 s``."""
        stop = ""
        if self.stop_reason is not None:
            why = self.stop_reason.value
            stop = f" ({why})" if self.stop_message in ("", why) else \
                f" ({why}: {self.stop_message})"
        return f"{self.phase.name}{stop} at {self.end_s:.2f} s"

    @property
    def verdict(self) -> str:
        """What the replay computed, in one line: the task's end when the commands were
        the recorded ones up to it; else unknown (open loop: after the divergence the
        measurements, and so the task's end, are the recorded run's)."""
        div = self.divergence
        if div is None or div.t_s > self.end_s:
            return (f"{self.ended}; the commands are the recorded ones up to it, so this "
                    "protocol ends so on this data")
        return (f"unknown: the commands differ from t = {div.t_s:.3f} s on, after which the "
                f"measurements answer the recorded commands; the task's {self.ended} "
                "judged the recorded run's world, not this protocol's")


def recorded_protocol(rec: Recording, overrides: Sequence[str] = ()) -> RunProtocol:
    """The protocol the recording was made with (metadata ``run.protocol_json``),
    with ``--set`` overrides (a scene key as ``scene.target.lateral=0.012``, as
    :func:`~ffexp.protocol.load_run_protocol` takes it); errors name the recording and
    the field."""
    source = f"{rec.path} (recorded protocol)"
    text = rec.metadata.get("run", {}).get("protocol_json")
    if not text:
        raise InputError(f"{rec.path}: metadata run.protocol_json is missing: the recording "
                         "does not say its protocol; give one with --protocol")
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"{rec.path}: metadata run.protocol_json is not JSON: {exc}") from None
    if not isinstance(data, dict):
        raise InputError(f"{rec.path}: metadata run.protocol_json is not a JSON object")
    return run_protocol_from(data, overrides, source)


class Inputs:
    """The per-cycle inputs of the loop, rebuilt from a recording."""

    def __init__(self, rec: Recording) -> None:
        if "/robot/state" not in rec.topics:
            raise InputError(f"{rec.path}: no topic /robot/state: the recording does not hold "
                             "what each cycle was fed (recorded before /robot/state existed?)")
        st = self.st = rec.topics["/robot/state"]
        if len(st) == 0:
            raise InputError(f"{rec.path}: /robot/state has no messages")
        self.path = rec.path
        self.log_ns = st.log_time_ns
        # log time = start + (robot time - robot time of the first cycle)
        self.t0_ns = int(st["time_ns"][0])
        self.start_ns = int(self.log_ns[0])
        self._split_ft(rec)
        pre = TRUTH_PREFIX
        self.truth = self._at_cycles(rec.topics.get(f"{pre}/truth"))
        #: per free body / named frame of the truth: (its data, its index per cycle)
        self.truth_parts = {
            (kind, topic.rsplit("/", 1)[1]): (data, self._at_cycles(data, keep=False))
            for topic, data in rec.topics.items()
            for kind in ("body", "site") if topic.startswith(f"{pre}/{kind}/")}
        tp = rec.topics.get("/target/pose")
        self.target_log_ns = tp.log_time_ns if tp is not None else np.zeros(0, np.int64)
        self.target = tp
        self.source = str(rec.metadata.get("run", {}).get("tracker", ""))

    def __len__(self) -> int:
        return len(self.st)

    def _split_ft(self, rec: Recording) -> None:
        ft = rec.topics.get("/ft/raw")
        n = len(self)
        if ft is None:
            self.ft_time = np.zeros(0, np.int64)
            self.ft_bounds = np.zeros(n + 1, np.int64)
            return
        self.ft_time = ft.log_time_ns - self.start_ns + self.t0_ns
        self.ft_seq = ft["seq"].astype(np.int64)
        self.ft_wrench = np.ascontiguousarray(ft["wrench"], dtype=np.float64)
        self.ft_status = ft["status"].astype(np.uint32)
        est = rec.topics.get("/estimator/state")
        counts = None
        if est is not None and np.array_equal(est.log_time_ns, self.log_ns):
            counts = est["n_samples"].astype(np.int64)
            if int(counts.sum()) != len(ft):
                counts = None  # not the samples the loop got (a cut file): by log time
        if counts is not None:
            self.ft_bounds = np.concatenate([[0], np.cumsum(counts)])
        else:
            upto = np.searchsorted(ft.log_time_ns, self.log_ns, side="right")
            self.ft_bounds = np.concatenate([[0], upto])

    def _at_cycles(self, data: TopicData | None, keep: bool = True) -> np.ndarray:
        """Per cycle, the index of ``data``'s message at the cycle's log time (-1: none);
        ``keep``: remember ``data`` as the truth's own topic."""
        out = np.full(len(self), -1, dtype=np.int64)
        if data is None or len(data) == 0:
            return out
        j = np.searchsorted(data.log_time_ns, self.log_ns)
        jc = np.minimum(j, len(data) - 1)
        hit = data.log_time_ns[jc] == self.log_ns
        out[hit] = jc[hit]
        if keep:
            self.truth_data = data
        return out

    def ft(self, i: int) -> FtSamples:
        a, b = int(self.ft_bounds[i]), int(self.ft_bounds[i + 1])
        if b <= a:
            return FtSamples()
        return FtSamples(self.ft_time[a:b], self.ft_seq[a:b], self.ft_wrench[a:b],
                         self.ft_status[a:b])

    def state(self, i: int) -> RobotState:
        st = self.st
        n_joints = min(int(st["n_joints"][i]), st["joint_pos"].shape[1])
        twist = st["twist"][i].copy() if st["has_twist"][i] else None
        ext = st["ext_wrench"][i].copy() if st["has_ext_wrench"][i] else None
        link = LinkHealth(bool(st["commanding"][i]), bool(st["healthy"][i]), int(st["cycle"][i]),
                          float(st["cycle_s"][i]))
        truth = None
        k = int(self.truth[i])
        if k >= 0:
            t = self.truth_data
            truth = GroundTruth(contact_wrench=t["contact_wrench"][k].copy(),
                                in_contact=bool(t["in_contact"][k]),
                                tcp_twist=t["tcp_twist"][k].copy())
            for (kind, name), (data, at) in self.truth_parts.items():
                j = int(at[i])
                if j < 0:
                    continue
                pose = data["pose"][j].reshape(4, 4).copy()
                if kind == "body":
                    truth.bodies[name] = BodyTruth(pose, data["twist"][j].copy(),
                                                   float(data["mass_kg"][j]))
                else:
                    truth.sites[name] = pose
        return RobotState(int(st["time_ns"][i]), st["tcp_pose"][i].reshape(4, 4).copy(),
                          st["joint_pos"][i][:n_joints].copy(), link, twist, ext, truth)

    def targets(self) -> Iterator[TargetObservation | None]:
        """Per cycle, the newest observation at or before its log time (one object per
        observation, as a tracker's ``latest()`` returns)."""
        tp = self.target
        idx = np.searchsorted(self.target_log_ns, self.log_ns, side="right") - 1
        last, obs = -1, None
        for j in idx.tolist():
            if j < 0 or tp is None:
                yield None
                continue
            if j != last:
                last = j
                obs = TargetObservation(int(tp["time_ns"][j]), tp["pose"][j].reshape(4, 4).copy(),
                                        tp["mouth"][j].reshape(4, 4).copy(), bool(tp["valid"][j]),
                                        self.source, int(tp["frames"][j]))
            yield obs


class _Commands:
    """The recorded ``/control/command`` per cycle, and the comparison with the replay's."""

    def __init__(self, rec: Recording, log_ns: np.ndarray) -> None:
        cmd = rec.topics.get("/control/command")
        self.row = np.full(len(log_ns), -1, dtype=np.int64)
        self.data = cmd
        if cmd is not None and len(cmd):
            j = np.minimum(np.searchsorted(cmd.log_time_ns, log_ns), len(cmd) - 1)
            hit = cmd.log_time_ns[j] == log_ns
            self.row[hit] = j[hit]
        self.first: Divergence | None = None
        self.diverging = 0
        self.max_diff = 0.0
        self._mine = {"given": np.zeros(1), "pose": np.zeros(16), "stiffness": np.zeros(6),
                      "damping": np.zeros(6), "wrench": np.zeros(6)}

    def applied(self, i: int, intent: CartesianCommand | None) -> AppliedCommand:
        """The replay's "applied" command: its intent, with the recorded status flags."""
        j, cmd = int(self.row[i]), self.data
        status = ApplyStatus(int(cmd["status"][j])) if cmd is not None and j >= 0 else \
            ApplyStatus.APPLIED
        if intent is not None:
            return AppliedCommand(intent, status)
        if cmd is None or j < 0:
            return AppliedCommand(CartesianCommand(), ApplyStatus.HELD)
        return AppliedCommand(CartesianCommand(
            cmd["applied_pose"][j].reshape(4, 4).copy(), cmd["applied_stiffness"][j].copy(),
            cmd["applied_damping"][j].copy(), cmd["applied_wrench"][j].copy()), status)

    def compare(self, i: int, t_ns: int, intent: CartesianCommand | None) -> Divergence | None:
        """Compare cycle ``i``'s intent with the recorded one; the divergence if it is the
        first cycle that differs."""
        j, cmd = int(self.row[i]), self.data
        if cmd is None or j < 0:
            return None
        mine = self._mine
        mine["given"][0] = float(intent is not None)
        for name in COMMAND_FIELDS[1:]:
            if intent is None:
                mine[name][:] = 0.0
        if intent is not None:
            mine["pose"][:] = intent.pose_m.reshape(-1)
            mine["stiffness"][:] = intent.stiffness_npm_nmprad
            mine["damping"][:] = intent.damping_ratio
            mine["wrench"][:] = intent.wrench_n_nm
        found: Divergence | None = None
        for name in COMMAND_FIELDS:
            rec_v = np.atleast_1d(cmd[name][j]).astype(np.float64)
            new_v = mine[name]
            d = np.abs(new_v - rec_v)
            self.max_diff = max(self.max_diff, float(d.max()))
            bad = ~within(rec_v, new_v, RTOL, ATOL)
            if found is None and bad.any():
                k = int(np.argmax(bad))
                label = name if rec_v.size == 1 else f"{name}_{k}"
                found = Divergence(t_ns / NS_PER_S, i, "/control/command", label,
                                   float(rec_v[k]), float(new_v[k]))
        if found is None:
            return None
        self.diverging += 1
        if self.first is not None:
            return None
        self.first = found
        return found


def replay(
    src: Path,
    out: Path,
    *,
    protocol_path: Path | None = None,
    overrides: Sequence[str] = (),
) -> ReplayResult:
    """Replay ``src`` through ``protocol_path`` (default: the recorded protocol) with
    ``overrides``, open loop; write the replay to ``out``."""
    from ffexp.runlog import RunLog

    if out.exists() and src.exists() and out.resolve() == src.resolve():
        raise InputError(f"{out}: --out must differ from the recording replayed")
    parts = [row["topic"] for row in contents(src).rows
             if str(row["topic"]).startswith(TRUTH_PART_PREFIXES)]
    rec = load(src, (*INPUT_TOPICS, *parts))
    lean = missing_topic(src, rec.metadata, rec.topics, ("/ft/raw", "/control/command"))
    if lean is not None:  # a lean recording has no F/T samples to replay
        raise InputError(lean)
    protocol = (load_run_protocol(protocol_path, list(overrides)) if protocol_path is not None
                else recorded_protocol(rec, overrides))
    inputs = Inputs(rec)
    commands = _Commands(rec, inputs.log_ns)
    cycles = 0
    with Recorder(out) as recorder:
        run_md = dict(rec.metadata.get("run", {}))
        run_md.update({
            "protocol": protocol.name, "method": protocol.method,
            "protocol_file": str(protocol_path) if protocol_path else run_md.get(
                "protocol_file", ""),
            "protocol_json": protocol.model_dump_json(), "overrides": json.dumps(list(overrides)),
            "run_name": out.stem, "replay_of": str(src),
        })
        recorder.metadata("run", run_md)
        log = RunLog(recorder, inputs.start_ns, protocol.run.tf_period_s)
        cyc: Cycle | None = None
        for i, target in zip(range(len(inputs)), inputs.targets(), strict=True):
            state, ft = inputs.state(i), inputs.ft(i)
            if cyc is None:
                cyc = Cycle(protocol, state, log)
                log.event(0, "INFO", "replay", f"replay of {src.name}: {OPEN_LOOP}")
            log.samples(cyc.t0_ns, ft)
            intent = cyc.step(state, ft, target)
            div = commands.compare(i, cyc.t_ns, intent)
            if div is not None:
                log.event(cyc.t_ns, "WARNING", "replay", div.line())
            cyc.record(state, ft, intent, commands.applied(i, intent))
            cycles += 1
            if cyc.task.finished(cyc.t_ns):
                break
            cyc.task.check_timeout(cyc.t_ns)
            cyc.flush_notes()
        assert cyc is not None  # Inputs refuses an empty /robot/state
        cyc.stop(Stop(StopReason.ROBOT_STOPPED, "end of the recording: no more measurements"))
        div = commands.first
        recorder.metadata("replay", {
            "source": str(src), "open_loop": OPEN_LOOP,
            "applied": "the replay's intent with the recorded status flags; without an intent, "
                       "the recorded applied command",
            "cycles": str(cycles), "recorded_cycles": str(len(inputs)),
            "diverges_at_s": "" if div is None else repr(div.t_s),
            "diverges_on": "" if div is None else f"{div.topic} {div.field}",
            "diverging_cycles": str(commands.diverging),
        })
        task = cyc.task
        stop = task.stop
        result = ReplayResult(out, cycles, len(inputs), commands.first, commands.diverging,
                              commands.max_diff, task.phase, stop.reason if stop else None,
                              stop.message if stop else "", cyc.t_ns / NS_PER_S, rec.warnings)
        recorder.metadata("replay_verdict", {"verdict": result.verdict})
    return result


__all__ = ["ATOL", "OPEN_LOOP", "RTOL", "Divergence", "Inputs", "ReplayResult",
           "recorded_protocol", "replay"]
