"""The task of a run: its phases, contact breaks and the hold of its goal.

Pure: no I/O, no clock. The loop feeds it one cycle at a time and writes the
notes it leaves (events, phase changes and verdicts, in order) to the run log.

Phases (:class:`ffexp.contracts.Phase`): CONNECT until the estimator has
tared with the robot commanding; APPROACH until contact; ALIGN while in
contact (contact lost goes back to APPROACH and counts a break, as the paper
does); DONE when the goal has held for the scenario's ``hold_s`` (unless
``end_on_aligned`` is off: then it is an ``aligned`` event and the run goes
on) or at the timeout; ABORT on any :class:`~ffexp.contracts.Stop` the loop
passes in.

What the goal is and who judges it belong to the run's scenario
(:mod:`ffexp.scenarios`, chosen by the protocol's ``[task] scenario``; the
paper's funnel alignment, :mod:`ffexp.scenarios.funnel`, by default). The task
asks it each cycle who judges and, in ALIGN, whether the goal holds; it times
the hold, and notes who judges (:class:`Verdict`, with an event when the judge
changes) and, at the end, the scenario's verdict of the run with its evidence.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drivers.base.types import NS_PER_S, RobotState, TargetObservation
from ffexp.contracts import Phase, Stop, StopReason
from ffexp.estimation import Estimate
from ffexp.scenarios.base import Scenario, Verdict
from ffexp.scenarios.funnel import Alignment  # where it was before scenarios (benchmarks)

#: The phases as module constants: an enum member read through its class costs about
#: 0.3 us in CPython 3.11 (a few of them each cycle), a global a few ns.
_CONNECT, _APPROACH, _ALIGN, _DONE, _ABORT = (
    Phase.CONNECT, Phase.APPROACH, Phase.ALIGN, Phase.DONE, Phase.ABORT)


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


Note = Event | PhaseChange | Verdict


class Task:
    """Phases, breaks and the verdict of one run.

    Args:
        scenario: the run's scenario (its goal and judges; :func:`ffexp.scenarios.build`
            makes the protocol's).
        timeout_s: run time after which the run ends (DONE, timeout).
        stop_hold_s: how long the safe stop is held before the run ends.
        end_on_aligned: end the run once the goal has held (DONE); False: note it
            and go on to the timeout (breaks after it still count).
    """

    def __init__(self, scenario: Scenario, timeout_s: float, stop_hold_s: float,
                 end_on_aligned: bool = True) -> None:
        self.scenario = scenario
        self.end_on_aligned = end_on_aligned
        self.timeout_ns = round(timeout_s * NS_PER_S)
        self.stop_hold_ns = round(stop_hold_s * NS_PER_S)
        self.phase = Phase.CONNECT
        self.phase_start_ns = 0
        self.contacts = 0
        self.breaks = 0
        self.aligned = False
        """The goal has held for the scenario's ``hold_s`` (the funnels aligned)."""
        self.stop: Stop | None = None
        self.end_ns: int | None = None
        """When the safe stop has been held long enough and the loop ends."""
        self.verdict: Verdict | None = None
        """The run's final verdict (set when the run ends)."""
        self.notes: list[Note] = []
        """Notes of the current cycle, oldest first; the loop empties it."""
        self._held_since_ns: int | None = None
        self.observed = False
        """The scenario watched this cycle (:meth:`Scenario.observe`): its measures are the
        cycle's, and the run log records them."""

    @property
    def verdict_source(self) -> str | None:
        """Who judges this cycle (``None`` before the first cycle of the approach)."""
        return self.scenario.source

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
        scenario = self.scenario
        self.observed = False
        event = est.event
        if event is not None:
            if event.kind == "made":
                self.contacts += 1
                self.notes.append(Event("INFO", "contact", f"contact made (#{self.contacts})"))
            else:
                self.notes.append(Event("WARNING", "contact", "contact broken"))
        phase = self.phase
        if phase is not _CONNECT:  # nothing is judged before the approach
            change = scenario.choose_source(state, target)
            if change is not None:
                self._held_since_ns = None
                self.notes.append(Event(change.level, "verdict_source", change.reason))
                self.notes.append(Verdict("unverified", change.source, change.reason, {},
                                          scenario.truth_label()))
        if phase is _CONNECT:
            if est.tared_now:
                bias = np.round(est.bias, 3).tolist()
                self.notes.append(
                    Event("INFO", "tare", f"tared from {est.tare_samples} samples; bias {bias}")
                )
                scenario.start(state)
                self._enter(t_ns, _APPROACH, "sensor tared, robot commanding")
            return
        if phase is _DONE or phase is _ABORT:  # phase.ended
            return
        scenario.observe(t_ns, state, est, target)
        self.observed = True
        if phase is _APPROACH:
            if est.in_contact:
                scenario.contact(state)
                self._enter(t_ns, _ALIGN, "contact")
        elif phase is _ALIGN:
            if not est.in_contact:
                self.breaks += 1
                self._held_since_ns = None
                scenario.contact_lost()
                self._enter(t_ns, _APPROACH, f"contact lost (break #{self.breaks})")
                return
            if scenario.holds(t_ns, state, est, target):
                if self._held_since_ns is None:
                    self._held_since_ns = t_ns
                if (t_ns - self._held_since_ns >= scenario.hold_s * NS_PER_S
                        and not self.aligned):
                    self.aligned = True
                    self.notes.append(Event("INFO", "aligned",
                                            f"{scenario.goal} (judged by {scenario.source})"))
                    if self.end_on_aligned:
                        self.end(t_ns, Stop(StopReason.ALIGNED, "aligned"))
            else:
                self._held_since_ns = None

    def _final_verdict(self) -> None:
        verdict = self.scenario.final(self.aligned)
        self.verdict = verdict
        self.notes.append(verdict)
        self.notes.append(Event("INFO", "verdict", f"{verdict.label} (judged by "
                                f"{verdict.source}; truth: {verdict.truth or 'n/a'}): "
                                f"{verdict.reason}"))


__all__ = ["Alignment", "Event", "Note", "PhaseChange", "Task", "Verdict"]
