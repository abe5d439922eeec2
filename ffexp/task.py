"""The task of a run: its phases, contact breaks and the alignment verdict.

Pure: no I/O, no clock. The loop feeds it one cycle at a time and writes the
notes it leaves (events and phase changes, in order) to the run log.

Phases (:class:`ffexp.contracts.Phase`): CONNECT until the estimator has
tared with the robot commanding; APPROACH until contact; ALIGN while in
contact (contact lost goes back to APPROACH and counts a break, as the paper
does); DONE when aligned for ``alignment.hold_s`` or at the timeout; ABORT
on any :class:`~ffexp.contracts.Stop` the loop passes in.

The verdict uses one set of tolerances, the protocol's ``[alignment]``: with
ground truth (a simulator) the tool tip's lateral and yaw errors within
tolerance past ``min_insertion_m``; without it, the tool advanced
``seated_depth_m`` since first contact with ``|w_y| <= lateral_force_n``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import Field

from drivers.base.types import F64, NS_PER_S, RobotState, TargetObservation
from drivers.config import StrictModel
from ffexp.contracts import Phase, Stop, StopReason
from ffexp.estimator import Estimate


class Alignment(StrictModel):
    """When the funnels count as aligned (one set of tolerances for every source)."""

    source: Literal["auto", "truth", "settings"] = Field(
        "auto", description="auto: ground truth when the robot reports it, else settings."
    )
    lateral_tol_m: float = Field(0.002, gt=0)
    yaw_tol_deg: float = Field(2.0, gt=0)
    min_insertion_m: float = Field(0.02, ge=0)
    seated_depth_m: float = Field(0.03, gt=0)
    lateral_force_n: float = Field(0.3, gt=0)
    hold_s: float = Field(0.2, ge=0)


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


Note = Event | PhaseChange


class Task:
    """Phases, breaks and the verdict of one run.

    Args:
        alignment: the protocol's tolerances.
        timeout_s: run time after which the run ends (DONE, timeout).
        stop_hold_s: how long the safe stop is held before the run ends.
    """

    def __init__(self, alignment: Alignment, timeout_s: float, stop_hold_s: float) -> None:
        self.alignment = alignment
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
        self.verdict_source: Literal["truth", "settings"] | None = None
        self.notes: list[Note] = []
        """Notes of the current cycle, oldest first; the loop empties it."""
        self._start_pose = np.eye(4)
        self._first_contact_z: float | None = None
        self._aligned_since_ns: int | None = None

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
        event = est.event
        if event is not None and event.kind == "made":
            self.contacts += 1
            self.notes.append(Event("INFO", "contact", f"contact made (#{self.contacts})"))
        elif event is not None:
            self.notes.append(Event("WARNING", "contact", "contact broken"))
        phase = self.phase
        if phase == Phase.CONNECT:
            if est.tared_now:
                bias = np.round(est.bias, 3).tolist()
                self.notes.append(
                    Event("INFO", "tare", f"tared from {est.tare_samples} samples; bias {bias}")
                )
                self._start_pose = state.tcp_pose_m.copy()
                self._enter(t_ns, Phase.APPROACH, "sensor tared, robot commanding")
        elif phase == Phase.APPROACH:
            if est.in_contact:
                if self._first_contact_z is None:
                    self._first_contact_z = float(self._tcf_offset(state)[2])
                self._enter(t_ns, Phase.ALIGN, "contact")
        elif phase == Phase.ALIGN:
            if not est.in_contact:
                self.breaks += 1
                self._aligned_since_ns = None
                self._enter(t_ns, Phase.APPROACH, f"contact lost (break #{self.breaks})")
                return
            if self.aligned_now(state, est):
                if self._aligned_since_ns is None:
                    self._aligned_since_ns = t_ns
                if t_ns - self._aligned_since_ns >= self.alignment.hold_s * NS_PER_S:
                    self.aligned = True
                    self.notes.append(Event("INFO", "aligned", "funnels aligned"))
                    self.end(t_ns, Stop(StopReason.ALIGNED, "aligned"))
            else:
                self._aligned_since_ns = None

    # -- the verdict ---------------------------------------------------------
    def _tcf_offset(self, state: RobotState) -> F64:
        d = state.tcp_pose_m[:3, 3] - self._start_pose[:3, 3]
        out: F64 = self._start_pose[:3, :3].T @ d
        return out

    def aligned_now(self, state: RobotState, est: Estimate) -> bool:
        """This cycle's verdict, before the hold time."""
        a = self.alignment
        truth = state.truth
        if a.source == "truth" or (a.source == "auto" and truth is not None):
            self.verdict_source = "truth"
            if truth is None:
                return False
            return (
                abs(truth.lateral_error) <= a.lateral_tol_m
                and abs(math.degrees(truth.yaw_error)) <= a.yaw_tol_deg
                and truth.insertion >= a.min_insertion_m
            )
        self.verdict_source = "settings"
        if self._first_contact_z is None:
            return False
        advanced = float(self._tcf_offset(state)[2]) - self._first_contact_z
        return advanced >= a.seated_depth_m and abs(float(est.wrench[1])) <= a.lateral_force_n
