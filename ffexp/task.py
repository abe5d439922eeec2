"""The task of a run: its phases, contact breaks and the alignment verdict.

Pure: no I/O, no clock. The loop feeds it one cycle at a time and writes the
notes it leaves (events and phase changes, in order) to the run log.

Phases (:class:`ffexp.contracts.Phase`): CONNECT until the estimator has
tared with the robot commanding; APPROACH until contact; ALIGN while in
contact (contact lost goes back to APPROACH and counts a break, as the paper
does); DONE when aligned for ``alignment.hold_s`` (unless ``end_on_aligned``
is off: then the seat is an ``aligned`` event and the run goes on) or at the
timeout; ABORT on any :class:`~ffexp.contracts.Stop` the loop passes in.

The verdict comes from whichever source sees the target (``[alignment]
source = "auto"``): ground truth in a simulator; else the rig's target
tracker, from the relative pose of the tool and the tracked funnel mouth
(:mod:`drivers.base.placement`); else the wrench-and-kinematics observer
(:mod:`ffexp.observer`), which says "aligned", "not aligned" or "unverified".
Truth and tracker share one set of tolerances: lateral and yaw errors within
tolerance past ``min_insertion_m``, held for ``hold_s``. A tracker pose that
is lost or older than ``tracker_max_age_s`` hands the verdict to the observer
until a fresh one arrives (an event says so). :class:`Verdict` notes record
who judges and, at the end, the run's verdict with its evidence and the
truth's verdict beside it (simulation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import Field

from drivers.base.placement import Placement, placement
from drivers.base.types import NS_PER_S, RobotState, TargetObservation
from drivers.config import StrictModel
from ffexp.contracts import Phase, Stop, StopReason
from ffexp.estimator import Estimate
from ffexp.observer import ObserverLimits, WrenchObserver


class Alignment(StrictModel):
    """When the funnels count as aligned, and who judges it.

    One set of tolerances (lateral, yaw, insertion, ``hold_s``) for every source
    that sees the target: ground truth (a simulator) and a target tracker (the
    relative pose of the tool and the tracked funnel mouth). Without either,
    the observer (:mod:`ffexp.observer`) judges with its own thresholds.
    """

    source: Literal["auto", "truth", "tracker", "observer", "settings"] = Field(
        "auto", description="auto: ground truth when the robot reports it, else the tracker "
        "when the rig has one, else the observer. settings: the old rule (advance "
        "seated_depth_m since first contact with |f_y| <= lateral_force_n), kept for "
        "comparison; it calls runs aligned that are not.")
    lateral_tol_m: float = Field(0.002, gt=0)
    yaw_tol_deg: float = Field(2.0, gt=0)
    min_insertion_m: float = Field(0.02, ge=0)
    hold_s: float = Field(0.2, ge=0)
    tracker_max_age_s: float = Field(
        0.25, gt=0, description="A tracker pose older than this does not judge (the observer "
        "does until a fresh one arrives).")
    seated_depth_m: float = Field(
        0.03, gt=0, description="Observer: insertion the funnels have when seated [m].")
    lateral_force_n: float = Field(0.3, gt=0, description="Observer: largest |f_y| when seated.")
    lateral_torque_nm: float = Field(
        0.05, gt=0, description="Observer: largest |t_x| (about the vertical) when seated.")
    wall_force_ratio: float = Field(
        0.5, gt=0, description="Observer: |f_y| / f_z at or above which (with |f_y| above "
        "lateral_force_n) the tool rests on one wall of the funnel: not aligned.")
    min_force_n: float = Field(0.3, ge=0, description="Observer: the tool must push this hard.")
    lateral_speed_mps: float = Field(
        0.002, gt=0, description="Observer: largest tool speed along Y when seated.")
    yaw_rate_dps: float = Field(1.0, gt=0, description="Observer: largest tool yaw rate.")
    observer_hold_s: float = Field(
        1.0, ge=0, description="Observer: how long its evidence must hold.")
    target_mass_kg: float = Field(
        12.0, gt=0, description="Observer: the target's mass (bounds how far pushing moved it).")


@dataclass(frozen=True)
class Event:
    """A note for ``/events``."""

    level: str
    name: str
    message: str


@dataclass(frozen=True)
class PhaseChange:
    """A note for ``/runner/phase`` (and ``/events``)."""

    old: Phase
    new: Phase
    reason: str
    stop: StopReason | None = None


@dataclass(frozen=True)
class Verdict:
    """A note for ``/alignment/verdict``: who judges the alignment and what it says.

    ``label`` is ``"aligned"``, ``"not aligned"`` or ``"unverified"``; ``truth`` is
    the simulator's verdict beside it (``""`` without ground truth), so a recording
    judged by a tracker or the observer can be scored against the truth.
    """

    label: str
    source: str
    reason: str
    evidence: dict[str, float]
    truth: str = ""
    final: bool = False


Note = Event | PhaseChange | Verdict

Source = Literal["truth", "tracker", "observer", "settings"]


class Task:
    """Phases, breaks and the verdict of one run.

    Args:
        alignment: the protocol's tolerances.
        timeout_s: run time after which the run ends (DONE, timeout).
        stop_hold_s: how long the safe stop is held before the run ends.
        end_on_aligned: end the run once aligned (DONE); False: note the seat and
            go on to the timeout (breaks after it still count).
    """

    def __init__(self, alignment: Alignment, timeout_s: float, stop_hold_s: float,
                 end_on_aligned: bool = True) -> None:
        self.alignment = alignment
        self.end_on_aligned = end_on_aligned
        self.timeout_ns = round(timeout_s * NS_PER_S)
        self.stop_hold_ns = round(stop_hold_s * NS_PER_S)
        self.phase = Phase.CONNECT
        self.phase_start_ns = 0
        self.contacts = 0
        self.breaks = 0
        self.aligned = False
        self.stop: Stop | None = None
        self.end_ns: int | None = None
        """When the safe stop has been held long enough and the loop ends."""
        self.verdict_source: Source | None = None
        """Who judges this cycle (``None`` before the first cycle)."""
        self.verdict: Verdict | None = None
        """The run's final verdict (set when the run ends)."""
        self.truth_aligned: bool | None = None
        """The truth's verdict beside whoever judges (``None`` without ground truth)."""
        self.placement: Placement | None = None
        """The latest relative pose of tool and funnel the judge used (truth or tracker)."""
        self.notes: list[Note] = []
        """Notes of the current cycle, oldest first; the loop empties it."""
        a = alignment
        self.observer = WrenchObserver(ObserverLimits(
            seated_depth_m=a.seated_depth_m, lateral_force_n=a.lateral_force_n,
            lateral_torque_nm=a.lateral_torque_nm, wall_force_ratio=a.wall_force_ratio,
            min_force_n=a.min_force_n,
            lateral_speed_mps=a.lateral_speed_mps, yaw_rate_radps=math.radians(a.yaw_rate_dps),
            hold_s=a.observer_hold_s, target_mass_kg=a.target_mass_kg))
        self._start_pose = np.eye(4)
        self._start_z_axis = np.array([0.0, 0.0, 1.0])
        self._start_z = 0.0
        self._first_contact_z: float | None = None
        self._aligned_since_ns: int | None = None
        self._truth_since_ns: int | None = None
        self._tracker_seen = False
        self._target: TargetObservation | None = None
        self._t_ns = 0

    # -- transitions ---------------------------------------------------------
    def _enter(self, t_ns: int, phase: Phase, reason: str, stop: StopReason | None = None) -> None:
        old = self.phase
        if phase == old:
            return
        self.phase = phase
        self.phase_start_ns = t_ns
        self.notes.append(PhaseChange(old, phase, reason, stop))

    def end(self, t_ns: int, stop: Stop) -> bool:
        """End the run (DONE or ABORT by the reason) unless it has ended; True if it did now."""
        if self.phase.ended:
            return False
        self.stop = stop
        self.end_ns = t_ns + self.stop_hold_ns
        self._enter(t_ns, stop.reason.phase, stop.message, stop.reason)
        self._final_verdict()
        return True

    def check_timeout(self, t_ns: int) -> None:
        """DONE (timeout) once the run time reaches the protocol's timeout."""
        if t_ns >= self.timeout_ns:
            self.end(t_ns, Stop(StopReason.TIMEOUT, "timeout"))

    def finished(self, t_ns: int) -> bool:
        """The safe stop has been held: the loop ends."""
        return self.end_ns is not None and t_ns >= self.end_ns

    # -- one cycle -----------------------------------------------------------
    def step(self, t_ns: int, state: RobotState, est: Estimate,
             target: TargetObservation | None = None) -> None:
        """Advance the phases by one cycle (after the safety checks); ``target`` is the
        tracker's newest observation of the target, if the rig has a tracker."""
        self._t_ns = t_ns
        self._target = target
        if target is not None:
            self._tracker_seen = True
        event = est.event
        if event is not None and event.kind == "made":
            self.contacts += 1
            self.notes.append(Event("INFO", "contact", f"contact made (#{self.contacts})"))
        elif event is not None:
            self.notes.append(Event("WARNING", "contact", "contact broken"))
        phase = self.phase
        if phase != Phase.CONNECT:  # nothing is judged before the approach
            self._choose_source(state, target)
        if phase == Phase.CONNECT:
            if est.tared_now:
                bias = np.round(est.bias, 3).tolist()
                self.notes.append(
                    Event("INFO", "tare", f"tared from {est.tare_samples} samples; bias {bias}")
                )
                self._start_pose = state.tcp_pose_m.copy()
                self._start_z_axis = self._start_pose[:3, 2].copy()
                self._start_z = float(self._start_z_axis @ self._start_pose[:3, 3])
                self._enter(t_ns, Phase.APPROACH, "sensor tared, robot commanding")
            return
        if phase.ended:
            return
        self._observe(t_ns, state, est)
        if phase == Phase.APPROACH:
            if est.in_contact:
                if self._first_contact_z is None:
                    self._first_contact_z = self._advance(state)
                self._enter(t_ns, Phase.ALIGN, "contact")
        elif phase == Phase.ALIGN:
            if not est.in_contact:
                self.breaks += 1
                self._aligned_since_ns = None
                self._truth_since_ns = None
                self._enter(t_ns, Phase.APPROACH, f"contact lost (break #{self.breaks})")
                return
            self._shadow_truth(t_ns, state)
            if self.aligned_now(state, est):
                if self._aligned_since_ns is None:
                    self._aligned_since_ns = t_ns
                if (t_ns - self._aligned_since_ns >= self.alignment.hold_s * NS_PER_S
                        and not self.aligned):
                    self.aligned = True
                    self.notes.append(Event("INFO", "aligned",
                                            f"funnels aligned (judged by {self.verdict_source})"))
                    if self.end_on_aligned:
                        self.end(t_ns, Stop(StopReason.ALIGNED, "aligned"))
            else:
                self._aligned_since_ns = None

    # -- the verdict ---------------------------------------------------------
    def _advance(self, state: RobotState) -> float:
        """The tool's travel along the start TCF's Z since the tare [m]."""
        return float(self._start_z_axis @ state.tcp_pose_m[:3, 3]) - self._start_z

    def _fresh(self, state: RobotState, target: TargetObservation | None) -> bool:
        if target is None or not target.valid:
            return False
        age_ns = state.time_ns - target.time_ns
        return age_ns <= self.alignment.tracker_max_age_s * NS_PER_S

    def _choose_source(self, state: RobotState, target: TargetObservation | None) -> None:
        want = self.alignment.source
        src: Source
        if want == "auto":
            if state.truth is not None:
                src = "truth"
            elif self._tracker_seen:
                src = "tracker" if self._fresh(state, target) else "observer"
            else:
                src = "observer"
        elif want == "tracker":
            src = "tracker" if self._fresh(state, target) else "observer"
        else:
            src = want
        if src == self.verdict_source:
            return
        old, self.verdict_source = self.verdict_source, src
        self._aligned_since_ns = None
        if old is None:
            reason = f"{src} judges the alignment"
            level = "INFO"
        elif old == "tracker":
            if target is None or not target.valid:
                why = f"lost ({target.status})" if target is not None and target.status \
                    else "lost"
            else:
                why = "stale"
            reason = f"the tracker's pose is {why}: the observer judges until it returns"
            level = "WARNING"
        else:
            reason = f"{src} judges the alignment again"
            level = "INFO"
        self.notes.append(Event(level, "verdict_source", reason))
        self.notes.append(Verdict("unverified", src, reason, {}, self._truth_label()))

    def _observe(self, t_ns: int, state: RobotState, est: Estimate) -> None:
        if state.truth is not None and self.truth_aligned is None:
            self.truth_aligned = False  # the truth is there: it says "not aligned" until held
        self._place(state)
        z = self._advance(state)
        if est.in_contact:
            self.observer.contact_made(z)
        w, tw = est.wrench, est.twist_tcf
        self.observer.update(t_ns, z, est.in_contact, est.f_z, float(w[1]), float(w[3]),
                             float(tw[1]), float(tw[3]))

    def _within(self, p: Placement) -> bool:
        a = self.alignment
        return (abs(p.lateral) <= a.lateral_tol_m and abs(math.degrees(p.yaw)) <= a.yaw_tol_deg
                and p.insertion >= a.min_insertion_m)

    def _shadow_truth(self, t_ns: int, state: RobotState) -> None:
        truth = state.truth
        if truth is None:
            return
        if self.truth_aligned is None:
            self.truth_aligned = False
        p = Placement((truth.insertion, truth.lateral_error, truth.vertical_error,
                       truth.yaw_error))
        if not self._within(p):
            self._truth_since_ns = None
            return
        if self._truth_since_ns is None:
            self._truth_since_ns = t_ns
        if t_ns - self._truth_since_ns >= self.alignment.hold_s * NS_PER_S:
            self.truth_aligned = True

    def _truth_label(self) -> str:
        """The truth's verdict: held within tolerance for ``hold_s``, or within it when
        the run ended (another judge may end the run before the truth's own hold)."""
        if self.truth_aligned is None:
            return ""
        within = self._truth_since_ns is not None
        return "aligned" if self.truth_aligned or within else "not aligned"

    def _place(self, state: RobotState) -> None:
        """The relative pose of tool and funnel the judging source sees (truth, tracker)."""
        src = self.verdict_source
        if src == "truth":
            truth = state.truth
            self.placement = None if truth is None else Placement(
                (truth.insertion, truth.lateral_error, truth.vertical_error, truth.yaw_error))
        elif src == "tracker":
            target = self._target
            self.placement = (None if target is None
                              else placement(state.tcp_pose_m, target.mouth_m))

    def aligned_now(self, state: RobotState, est: Estimate) -> bool:
        """This cycle's verdict of the judging source, before the hold time."""
        src = self.verdict_source
        if src in ("truth", "tracker"):
            self._place(state)
            return self.placement is not None and self._within(self.placement)
        if src == "settings":
            if self._first_contact_z is None:
                return False
            advanced = self._advance(state) - self._first_contact_z
            a = self.alignment
            return advanced >= a.seated_depth_m and abs(float(est.wrench[1])) <= a.lateral_force_n
        # the observer holds its own evidence for observer_hold_s; the task's hold adds to it
        return self.observer.state.label == "aligned"

    def _final_verdict(self) -> None:
        src = self.verdict_source or "observer"
        truth = self._truth_label()
        if src == "observer":
            obs = self.observer.state
            label = "aligned" if self.aligned else self.observer.final()
            if label == "aligned" and not self.aligned:
                label = "unverified"  # seen aligned, but the run ended before the hold
            reason = {"aligned": "robot-side evidence of seated cones held",
                      "not aligned": "the tool rests on one wall of the funnel, or is "
                                     "out of contact behind where it first touched",
                      "unverified": "the robot alone cannot tell where the target is"}[label]
            verdict = Verdict(label, src, reason, dict(obs.evidence), truth, True)
        else:
            label = "aligned" if self.aligned else "not aligned"
            evidence: dict[str, float] = {}
            p = self.placement
            if p is not None:
                evidence = {"insertion_m": p.insertion, "lateral_m": p.lateral,
                            "vertical_m": p.vertical, "yaw_deg": math.degrees(p.yaw)}
            reason = (f"{src}: relative pose within tolerance for {self.alignment.hold_s} s"
                      if self.aligned else f"{src}: never within tolerance for "
                      f"{self.alignment.hold_s} s")
            verdict = Verdict(label, src, reason, evidence, truth, True)
        self.verdict = verdict
        self.notes.append(verdict)
        self.notes.append(Event("INFO", "verdict", f"{label} (judged by {src}; truth: "
                                f"{truth or 'n/a'}): {reason}"))
