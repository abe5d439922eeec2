"""Metrics and table rows from run recordings (the figures: :mod:`ffexp.figures`).

Everything here reads a :class:`~ffexp.recording.Recording`; a run's numbers
are never taken from anywhere else, so ``ffexp run``, ``ffexp analyze`` and
``ffexp compare`` agree by construction.

Times are seconds since the run's first cycle. "In ALIGN" means the cycles
whose ``/control/terms.phase`` is ALIGN. The approach-axis contact force is
``f_z = -w[2]`` (positive while pushing); lateral contact force and torque are
plotted as measured, ``w[1]`` and ``w[3]`` (the environment on the tool), so
that the applied inertia-reduction terms ``k w`` are visibly proportional.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from drivers import registry
from drivers.base.types import NS_PER_S as NS
from ffexp import controllers, impulse
from ffexp.contracts import Phase, StopReason
from ffexp.errors import InputError
from ffexp.linkcheck import check_link
from ffexp.outcome import ALIGNED as ALIGNED_OUTCOME
from ffexp.outcome import Outcome, RunFacts, agreement, classify
from ffexp.recording import Recording

ALIGN = Phase.ALIGN
#: f_z tracking is scored after this long in each ALIGN segment.
SETTLE_S = 1.0


@dataclass
class RunMetrics:
    """The numbers of one run (``ffexp analyze --json`` prints these keys)."""

    protocol: str
    method: str
    aligned: bool
    alignment_time_s: float | None
    first_contact_s: float | None
    contact_breaks: int
    """Contact lost after the first contact, in the whole run (a run that goes on
    after a momentary seat counts what follows it)."""
    break_times_s: list[float]
    breaks_align: int
    """Contact lost within ALIGN before the funnels were aligned."""
    mean_fz_align_n: float | None
    peak_abs_fz_n: float | None
    fz_tracking_rmse_n: float | None
    f_ref_n: float | None
    target_speed_after_contact_mps: float | None
    target_max_speed_mps: float | None
    target_displacement_m: float | None
    final_lateral_error_m: float | None
    final_yaw_error_deg: float | None
    target_momentum_ns: float | None
    """The target's momentum change over the run, from the simulator's truth [N s]."""
    contact_impulse_ns: float | None
    """The impulse the F/T sensor measured on the tool, in the world frame [N s] (the
    estimator's compensated wrench)."""
    base_max_displacement_m: float | None
    """A floating base's largest distance from where it started (``None``: fixed)."""
    base_max_rotation_deg: float | None
    """A floating base's largest rotation from its start attitude."""
    mean_abs_wrench_align: list[float] | None
    peak_abs_wrench_align: list[float] | None
    duration_s: float
    aborted: str | None
    link: dict[str, float]
    complete: bool = True
    warnings: list[str] = field(default_factory=list)
    peak_abs_fz_run_n: float | None = None
    """Peak |f_z| over the whole run after the tare (APPROACH re-contacts included);
    ``peak_abs_fz_n`` is ALIGN's only."""
    peak_abs_wrench_run: list[float] | None = None
    verdict: str | None = None
    """The run's verdict: aligned, not aligned or unverified (``None``: not recorded)."""
    verdict_source: str | None = None
    """Who judged: truth, tracker, observer or settings."""
    verdict_truth: str | None = None
    """The simulator's verdict beside it (``None`` without ground truth)."""
    verdict_evidence: dict[str, float] = field(default_factory=dict)
    trial_valid: bool | None = None
    """The link's verdict on the trial (:mod:`ffexp.linkcheck`); None: unknown, the run's
    end is not recorded (``complete`` false)."""
    trial_validity: str = ""
    """The same in words: valid, invalid: REASONS, or unknown: the run ended abnormally."""
    outcome: str = ""
    """What happened, by :func:`ffexp.outcome.classify`: aligned, contact kept breaking,
    held contact, did not slide, pushed away, no contact; or (not scored) incomplete,
    stopped, aborted."""
    outcome_note: str = ""
    """Beside the outcome: a seat that was not kept, the final errors of a jam, an abort."""
    transient_end_s: float | None = None
    """End of the first contact's transient (where the contact settled; :mod:`ffexp.outcome`)."""
    breaks_after_transient: int = 0
    ended_aligned: bool = False
    """The run ended DONE on its seat (not a seat noted on the way to a timeout)."""

    def to_json(self) -> str:
        return json.dumps(asdict(self), allow_nan=False, default=_json_default)


def _json_default(x: object) -> object:
    if isinstance(x, np.generic):
        return x.item()
    raise TypeError(type(x).__name__)


@dataclass
class RunSeries:
    """Per-cycle series of a run, aligned on the controller cycles."""

    t_s: np.ndarray
    phase: np.ndarray
    wrench: np.ndarray
    applied: np.ndarray
    f_ref: np.ndarray
    in_contact: np.ndarray


def series(rec: Recording) -> RunSeries:
    """The per-cycle signals the metrics and figures use."""
    est = rec.topic("/estimator/state")
    ctl = rec.topic("/control/terms")
    # a cut file (killed run, recovered) may end between a cycle's two messages:
    # keep the cycles both topics have
    times, ie, ic = np.intersect1d(est.log_time_ns, ctl.log_time_ns, return_indices=True)
    if len(times) == 0:
        raise InputError(f"{rec.path}: no controller cycles recorded")
    t0 = int(times[0])
    return RunSeries(
        t_s=(times - t0) / NS,
        phase=ctl["phase"][ic],
        wrench=est["wrench"][ie],
        applied=ctl["total"][ic],
        f_ref=ctl["f_ref"][ic],
        in_contact=est["in_contact"][ie].astype(bool),
    )


def run_info(rec: Recording) -> dict[str, Any]:
    """The run metadata (protocol name, method, ...) as recorded."""
    meta = rec.metadata.get("run", {})
    out: dict[str, Any] = dict(meta)
    try:
        out["protocol_resolved"] = json.loads(meta.get("protocol_json", "{}"))
    except json.JSONDecodeError:
        out["protocol_resolved"] = {}
    return out


def metrics(rec: Recording) -> RunMetrics:
    """Compute a run's metrics from its recording."""
    s = series(rec)
    info = run_info(rec)
    t0_ns = int(rec.topic("/estimator/state").log_time_ns[0])
    phases = rec.json.get("/runner/phase")
    aborted: str | None = None
    stop_reason: str | None = None
    aligned_at: float | None = None
    ended_aligned = False
    if phases is not None:
        for t_ns, msg in zip(phases.log_time_ns.tolist(), phases.messages, strict=True):
            phase = _phase_of(msg)
            if phase == Phase.ABORT:
                aborted = str(msg.get("reason", "aborted"))
                stop_reason = str(msg.get("stop_reason") or "aborted")
            if phase == Phase.DONE and _ended_aligned(msg):
                aligned_at = (t_ns - t0_ns) / NS
                ended_aligned = True
    events = rec.json.get("/events")
    if aligned_at is None and events is not None:  # a run that went on after its seat
        for t_ns, msg in zip(events.log_time_ns.tolist(), events.messages, strict=True):
            if msg.get("name") == "aligned":
                aligned_at = (t_ns - t0_ns) / NS
                break
    contact = s.in_contact
    made = np.flatnonzero(~contact[:-1] & contact[1:]) + 1
    first_contact = float(s.t_s[made[0]]) if made.size else (
        float(s.t_s[0]) if contact.size and contact[0] else None
    )
    lost = np.flatnonzero(contact[:-1] & ~contact[1:]) + 1
    # every break after the first contact; and those within ALIGN before the seat
    breaks = [float(s.t_s[i]) for i in lost]
    breaks_align = [t for i, t in zip(lost.tolist(), breaks, strict=True)
                    if s.phase[i - 1] == ALIGN and (aligned_at is None or t <= aligned_at)]
    in_align = s.phase == ALIGN
    f_z = -s.wrench[:, 2]
    mean_fz = peak_fz = rmse = None
    mean_w = peak_w = None
    f_ref = None
    if in_align.any():
        mean_fz = float(np.mean(f_z[in_align]))
        peak_fz = float(np.max(np.abs(f_z[in_align])))
        mean_w = np.mean(np.abs(s.wrench[in_align]), axis=0).tolist()
        peak_w = np.max(np.abs(s.wrench[in_align]), axis=0).tolist()
        force_control = controllers.tracks_force_reference(str(info.get("method", "")))
        f_ref = float(np.median(s.f_ref[in_align, 2])) if force_control else None
        settled = in_align & (_time_in_phase(s) >= SETTLE_S)
        if settled.any() and force_control:
            rmse = float(np.sqrt(np.mean((f_z[settled] - s.f_ref[settled, 2]) ** 2)))
    speed_mean = speed_max = disp = lat = yaw = momentum = None
    body = rec.topics.get("/sim/body/target")
    if body is not None and len(body):
        tt = (body.log_time_ns - t0_ns) / NS
        speed = np.linalg.norm(body["twist"][:, :3], axis=1)
        after = tt >= first_contact if first_contact is not None else np.zeros_like(tt, bool)
        if after.any():
            speed_mean = float(np.mean(speed[after]))
            speed_max = float(np.max(speed[after]))
            p0 = body["pose"][after][0].reshape(4, 4)[:3, 3]
            p1 = body["pose"][-1].reshape(4, 4)[:3, 3]
            disp = float(np.linalg.norm(p1 - p0))
        momentum = impulse.momentum_change_ns(float(body["mass_kg"][-1]), body["twist"])
    placed = rec.topics.get("/task/funnel")
    if placed is not None and len(placed):
        lat = float(placed["lateral"][-1])
        yaw = math.degrees(float(placed["yaw"][-1]))
    contact_impulse = _contact_impulse(rec, t0_ns)
    base_move = base_turn = None
    base = rec.topics.get("/sim/body/chaser")
    if base is not None and len(base):
        base_move, base_turn = impulse.base_excursion(base["pose"].reshape(-1, 4, 4))
    link = _link_summary(rec)
    after_tare = s.phase != Phase.CONNECT
    peak_run = peak_w_run = None
    if after_tare.any():
        peak_run = float(np.max(np.abs(f_z[after_tare])))
        peak_w_run = np.max(np.abs(s.wrench[after_tare]), axis=0).tolist()
    v = final_verdict(rec)
    replayed = rec.metadata.get("replay_verdict", {}).get("verdict", "")
    if replayed.startswith("unknown"):  # an open-loop replay whose commands diverged
        v = {**v, "label": "unknown", "source": "replay (open loop, diverged)"}
    trial = check_link(rec)
    # the run's own contact history: up to its end (DONE or ABORT), not the safe stop's
    ended = np.flatnonzero((s.phase == Phase.DONE) | (s.phase == Phase.ABORT))
    last = int(ended[0]) if ended.size else len(s.t_s) - 1
    said = classify(RunFacts(
        made_s=([float(s.t_s[0])] if contact.size and contact[0] else [])
        + [float(s.t_s[i]) for i in made if i <= last],
        lost_s=[float(s.t_s[i]) for i in lost if i <= last], end_s=float(s.t_s[last]),
        in_contact_at_end=bool(contact.size and contact[last]), seated_s=aligned_at,
        complete=rec.complete, stop_reason=stop_reason, abort_message=aborted,
        lateral_error_m=lat, yaw_error_deg=yaw))
    return RunMetrics(
        protocol=str(info.get("protocol", rec.path.stem)),
        method=str(info.get("method", "")),
        aligned=aligned_at is not None,
        alignment_time_s=aligned_at,
        first_contact_s=first_contact,
        contact_breaks=len(breaks),
        break_times_s=breaks,
        breaks_align=len(breaks_align),
        mean_fz_align_n=mean_fz,
        peak_abs_fz_n=peak_fz,
        fz_tracking_rmse_n=rmse,
        f_ref_n=f_ref,
        target_speed_after_contact_mps=speed_mean,
        target_max_speed_mps=speed_max,
        target_displacement_m=disp,
        final_lateral_error_m=lat,
        final_yaw_error_deg=yaw,
        target_momentum_ns=momentum,
        contact_impulse_ns=contact_impulse,
        base_max_displacement_m=base_move,
        base_max_rotation_deg=base_turn,
        mean_abs_wrench_align=mean_w,
        peak_abs_wrench_align=peak_w,
        duration_s=float(s.t_s[-1]),
        aborted=aborted,
        link=link,
        complete=rec.complete,
        warnings=list(rec.warnings),
        peak_abs_fz_run_n=peak_run,
        peak_abs_wrench_run=peak_w_run,
        verdict=v.get("label") if v else None,
        verdict_source=v.get("source") if v else None,
        verdict_truth=(v.get("truth") or None) if v else None,
        verdict_evidence={k: float(x) for k, x in (v.get("evidence") or {}).items()} if v else {},
        trial_valid=trial.trial_valid,
        trial_validity=trial.validity,
        outcome=said.label,
        outcome_note=said.note,
        transient_end_s=said.transient.end_s,
        breaks_after_transient=said.breaks_after_transient,
        ended_aligned=ended_aligned,
    )


def _contact_impulse(rec: Recording, t0_ns: int) -> float | None:
    """The contact impulse in the world frame (:func:`ffexp.impulse.contact_impulse_ns`):
    the TCF's world orientation from the simulator's TCP frame when recorded (a floating
    base moves the robot's base frame), else the robot's pose (its base is the world)."""
    est = rec.topic("/estimator/state")
    tcp = rec.topics.get("/sim/site/tcp")
    frame = tcp["pose"] if tcp is not None else None
    if frame is None or len(frame) != len(est):
        st = rec.topics.get("/robot/state")
        if st is None or len(st) != len(est):
            return None
        frame = st["tcp_pose"]
    rot = frame.reshape(-1, 4, 4)[:, :3, :3]
    # contact in APPROACH and ALIGN only: the safe stop's jerk is no contact
    ctl = rec.topics.get("/control/terms")
    touching = est["in_contact"].astype(bool)
    if ctl is not None and np.array_equal(ctl.log_time_ns, est.log_time_ns):
        touching &= (ctl["phase"] == Phase.APPROACH) | (ctl["phase"] == Phase.ALIGN)
    return impulse.contact_impulse_ns((est.log_time_ns - t0_ns) / NS, est["wrench"], rot,
                                      touching)


def final_verdict(rec: Recording) -> dict[str, Any]:
    """The run's final ``/alignment/verdict`` message (``{}`` if none was recorded)."""
    topic = rec.json.get("/alignment/verdict")
    if topic is None:
        return {}
    last: dict[str, Any] = {}
    for msg in topic.messages:
        if msg.get("final"):
            last = msg
    return last


def _phase_of(msg: dict[str, Any]) -> Phase | None:
    """The phase of a ``/runner/phase`` message (by its id)."""
    try:
        return Phase(int(msg.get("phase_id", -1)))
    except ValueError:
        return None


def _ended_aligned(msg: dict[str, Any]) -> bool:
    """A DONE message says the run ended aligned (its flag; files before the flag: the
    reason that the stop reason's value then was)."""
    if "aligned" in msg:
        return bool(msg["aligned"])
    return msg.get("reason") == StopReason.ALIGNED.value


def _time_in_phase(s: RunSeries) -> np.ndarray:
    """Seconds since the current phase segment began, per cycle."""
    starts = np.concatenate([[True], s.phase[1:] != s.phase[:-1]])
    seg_start_t = s.t_s[starts]
    seg_index = np.cumsum(starts) - 1
    out: np.ndarray = s.t_s - seg_start_t[seg_index]
    return out


def _link_summary(rec: Recording) -> dict[str, float]:
    """The link's statistics the back-ends state (:func:`drivers.registry.link_stats`),
    those the recording has."""
    out: dict[str, float] = {}
    for stat in registry.link_stats():
        data = rec.topics.get(stat.topic)
        if data is None or len(data) == 0:
            continue
        if stat.reduce == "count":
            out[stat.name] = float(len(data))
            continue
        if stat.field not in data.fields:
            continue
        v = data[stat.field]
        out[stat.name] = float(
            np.min(v) if stat.reduce == "min" else np.max(v) if stat.reduce == "max"
            else v[-1] if stat.reduce == "last" else np.mean(v < stat.below))
    return out


# -- tables ----------------------------------------------------------------------
#: The comparison table: (title, key, priority). Priority 0 is always shown; a
#: narrow terminal drops the highest numbers first (``--wide`` shows all).
COMPARE_COLUMNS: tuple[tuple[str, str, int], ...] = (
    ("run", "run", 0),
    ("protocol", "protocol", 9),
    ("method", "method", 8),
    ("f_ref [N]", "f_ref_n", 3),
    ("k_xp", "k_xp", 6),
    ("k_yp", "k_yp", 6),
    ("contact [s]", "first_contact_s", 2),
    ("aligned [s]", "alignment_time_s", 0),
    ("breaks", "contact_breaks", 1),
    ("breaks ALIGN", "breaks_align", 3),
    ("verdict", "verdict", 0),
    ("outcome", "outcome", 0),
    ("judge", "verdict_source", 2),
    ("mean f_z [N]", "mean_fz_align_n", 4),
    ("peak |f_z| ALIGN [N]", "peak_abs_fz_n", 7),
    ("peak |f_z| run [N]", "peak_abs_fz_run_n", 7),
    ("f_z rmse [N]", "fz_tracking_rmse_n", 5),
    ("target v [m/s]", "target_speed_after_contact_mps", 7),
    ("momentum [N s]", "target_momentum_ns", 0),
    ("end", "end", 0),
    ("complete", "complete", 1),
)
#: Keys of a comparison row as data (``compare --csv/--json``), in column order.
COMPARE_KEYS: tuple[str, ...] = (
    "file", "run", "complete", "protocol", "method", "overrides", "f_ref_n", "k_xp", "k_yp",
    "aligned", "verdict", "verdict_source", "verdict_truth", "outcome", "first_contact_s",
    "alignment_time_s", "contact_breaks", "breaks_align", "mean_fz_align_n", "peak_abs_fz_n",
    "peak_abs_fz_run_n", "fz_tracking_rmse_n", "target_speed_after_contact_mps",
    "target_max_speed_mps", "target_displacement_m", "final_lateral_error_m",
    "final_yaw_error_deg", "target_momentum_ns", "contact_impulse_ns",
    "base_max_displacement_m", "base_max_rotation_deg", "duration_s", "end", "aborted",
    "trial_valid", "trial_validity", "source_revision",
)


def run_name(rec: Recording) -> str:
    """The run's name: the one it was recorded under (metadata), else the file's stem."""
    return str(rec.metadata.get("run", {}).get("run_name") or rec.path.stem)


def end_label(m: RunMetrics) -> str:
    """How the run ended, in one word or reason: the abort reason, aligned, or timeout
    (a run that went on after its seat and was then aborted ends with the abort; one
    whose seat did not last to its end, with its timeout)."""
    if m.aborted is not None:
        return m.aborted
    if m.ended_aligned or (m.aligned and m.outcome in ("", ALIGNED_OUTCOME)):
        return "aligned"
    return "timeout" if m.complete else "cut"


def compare_row(rec: Recording, m: RunMetrics | None = None) -> dict[str, Any]:
    """One run's row (keys :data:`COMPARE_KEYS`); missing values are None."""
    m = metrics(rec) if m is None else m
    info = run_info(rec)
    proto = info.get("protocol_resolved", {})
    k_ri = proto.get("align", {}).get("k_ri")
    values: dict[str, Any] = asdict(m)
    values["k_xp"], values["k_yp"] = (k_ri[3], k_ri[1]) if k_ri else (None, None)
    if not controllers.tracks_force_reference(m.method):
        values["f_ref_n"] = None
    try:
        overrides = json.loads(info.get("overrides", "[]"))
    except json.JSONDecodeError:
        overrides = []
    values.update(
        file=str(rec.path),
        run=run_name(rec),
        overrides=" ".join(str(o) for o in overrides),
        end=end_label(m),
        outcome=outcome(m).text(),
        source_revision=info.get("source_revision"),
    )
    return {key: values.get(key) for key in COMPARE_KEYS}


#: The paper's Table res_par beside ours: (title, key, priority).
PAPER_COLUMNS: tuple[tuple[str, str, int], ...] = (
    ("run", "run", 0), ("f_ref [N]", "f_ref_n", 3), ("k_xp", "k_xp", 4), ("k_yp", "k_yp", 4),
    ("paper", "paper_outcome", 0), ("ours", "outcome", 0), ("agree", "agree", 0),
    ("paper start [s]", "paper_start_s", 3),
    ("paper contact [s]", "paper_contact_s", 1), ("ours contact [s]", "contact_s", 1),
    ("paper end [s]", "paper_end_s", 1), ("ours aligned [s]", "aligned_s", 1),
    ("breaks", "breaks", 0), ("breaks ALIGN", "breaks_align", 2), ("ours end", "end", 2),
)

def outcome(m: RunMetrics) -> Outcome:
    """The run's outcome as :func:`metrics` named it (:mod:`ffexp.outcome`)."""
    return Outcome(m.outcome, m.outcome_note, breaks_after_transient=m.breaks_after_transient)


def paper_row(rec: Recording, m: RunMetrics | None = None) -> dict[str, Any] | None:
    """The paper's values for this run beside ours, from the recorded protocol's
    ``paper`` table (its times as the paper gives them, on its clock, which starts
    the experiment at ``paper_start_s``; ours since the tare); None without one."""
    m = metrics(rec) if m is None else m
    proto = run_info(rec).get("protocol_resolved", {})
    paper = proto.get("paper") or {}
    if not paper:
        return None
    align = proto.get("align", {})
    k_ri = align.get("k_ri")
    f_ref = align.get("f_ref")
    force = controllers.tracks_force_reference(m.method)
    ours = outcome(m)
    theirs = paper.get("outcome")
    return {
        "run": run_name(rec),
        "paper_outcome": theirs,
        "outcome": ours.text(),
        "agree": agreement(None if theirs is None else str(theirs), ours),
        "f_ref_n": f_ref[2] if force and f_ref else None,
        "k_xp": k_ri[3] if k_ri else None,
        "k_yp": k_ri[1] if k_ri else None,
        "paper_start_s": paper.get("start_s"),
        "paper_contact_s": paper.get("contact_s"),
        "contact_s": m.first_contact_s,
        "paper_end_s": paper.get("end_s"),
        "aligned_s": m.alignment_time_s,
        "breaks": m.contact_breaks,
        "breaks_align": m.breaks_align,
        "end": end_label(m),
    }
