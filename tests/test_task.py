"""The Task's phases and its alignment verdict: one set of tolerances, the protocol's."""

from __future__ import annotations

import math

import numpy as np
import pytest
from funnel_truth import funnel_truth
from loop_script import pose_at

from drivers.base.types import GroundTruth, RobotState
from ffexp.contracts import Phase, Stop, StopReason
from ffexp.estimation import ContactEvent, Estimate
from ffexp.scenarios.funnel import Alignment, FunnelAlignment
from ffexp.task import PhaseChange, Task

NS = 1_000_000_000


def in_align(alignment: Alignment, end_on_aligned: bool = True) -> Task:
    task = Task(FunnelAlignment(alignment), timeout_s=30.0, stop_hold_s=0.1,
                end_on_aligned=end_on_aligned)
    s = RobotState(tcp_pose_m=pose_at(0.0))
    task.step(0, s, Estimate(tared_now=True, tared=True))
    task.step(5_000_000, s, Estimate(tared=True, in_contact=True,
                                      event=ContactEvent("made", 5_000_000, 0.0)))
    assert task.phase is Phase.ALIGN
    task.notes.clear()
    return task


def truth(
    lateral_m: float, yaw_deg: float, insertion_m: float, seated: bool = False
) -> GroundTruth:
    return funnel_truth(insertion_m, lateral_m, 0.0, math.radians(yaw_deg))


def hold(task: Task, t: GroundTruth | None, seconds: float, z: float = 0.0) -> None:
    """Step the task for ``seconds`` more of run time with the same state."""
    s = RobotState(tcp_pose_m=pose_at(z), truth=t)
    est = Estimate(tared=True, in_contact=True)
    t0 = getattr(task, "_test_clock_ns", task.phase_start_ns)
    k = 0
    for k in range(1, round(seconds / 0.005) + 1):
        task.step(t0 + k * 5_000_000, s, est)
    task._test_clock_ns = t0 + k * 5_000_000  # type: ignore[attr-defined]


@pytest.mark.parametrize(
    ("lateral", "yaw", "insertion", "aligned"),
    [(0.001, 1.0, 0.03, True), (0.0025, 1.0, 0.03, False), (0.001, 2.5, 0.03, False),
     (0.001, 1.0, 0.01, False), (-0.0019, -1.9, 0.021, True)],
)
def test_truth_verdict_uses_the_protocols_tolerances(
    lateral: float, yaw: float, insertion: float, aligned: bool
) -> None:
    task = in_align(Alignment(hold_s=0.2))
    hold(task, truth(lateral, yaw, insertion), 0.3)
    assert task.aligned is aligned
    assert task.verdict_source == "truth"
    if aligned:
        assert task.phase is Phase.DONE and task.stop is not None
        assert task.stop.reason is StopReason.ALIGNED


def test_the_simulators_own_seating_flag_does_not_override_the_protocol() -> None:
    task = in_align(Alignment(lateral_tol_m=0.001))
    hold(task, truth(0.0015, 0.5, 0.03, seated=True), 0.5)
    assert not task.aligned


def test_a_verdict_must_hold_for_hold_s() -> None:
    task = in_align(Alignment(hold_s=0.2))
    hold(task, truth(0.0, 0.0, 0.03), 0.19)
    assert not task.aligned
    hold(task, truth(0.0, 0.0, 0.03), 0.02)
    assert task.aligned


def test_settings_verdict_only_when_asked() -> None:
    task = in_align(Alignment(source="settings", seated_depth_m=0.03, lateral_force_n=0.3))
    hold(task, None, 0.3, z=0.029)
    assert not task.aligned and task.verdict_source == "settings"
    hold(task, None, 0.3, z=0.031)
    assert task.aligned


def test_without_truth_or_tracker_the_observer_judges_and_does_not_call_a_push_aligned() -> None:
    # the old rule's case: 31 mm advanced, no lateral force; but the target floats
    task = in_align(Alignment())
    hold(task, None, 3.0, z=0.031)
    assert task.verdict_source == "observer"
    assert not task.aligned
def test_truth_source_without_truth_never_aligns() -> None:
    task = in_align(Alignment(source="truth"))
    hold(task, None, 0.5, z=0.1)
    assert not task.aligned


def test_contact_loss_counts_a_break_and_notes_in_order() -> None:
    task = in_align(Alignment())
    s = RobotState(tcp_pose_m=pose_at(0.0))
    task.step(NS, s, Estimate(tared=True, in_contact=False,
                              event=ContactEvent("broken", NS, 1.0)))
    assert task.phase is Phase.APPROACH and task.breaks == 1
    kinds = [type(n).__name__ for n in task.notes]
    assert kinds == ["Event", "PhaseChange"]
    change = task.notes[1]
    assert isinstance(change, PhaseChange) and change.reason == "contact lost (break #1)"


def test_a_run_that_goes_on_notes_its_seat_and_keeps_counting_breaks() -> None:
    """end_on_aligned off (the paper's Method III ran on): the seat is one 'aligned'
    event, the phase stays ALIGN, a later loss is a break, the timeout ends the run."""
    task = in_align(Alignment(hold_s=0.2), end_on_aligned=False)
    hold(task, truth(0.0, 0.0, 0.03), 0.5)
    assert task.aligned and task.phase is Phase.ALIGN and task.stop is None
    events = [n.name for n in task.notes if type(n).__name__ == "Event"]
    assert events.count("aligned") == 1  # noted once, not every cycle after the hold
    t = task._test_clock_ns + 5_000_000  # type: ignore[attr-defined]
    task.step(t, RobotState(tcp_pose_m=pose_at(0.0)),
              Estimate(tared=True, in_contact=False, event=ContactEvent("broken", t, 1.0)))
    assert task.phase is Phase.APPROACH and task.breaks == 1
    task.check_timeout(30 * NS)
    assert task.stop is not None and task.stop.reason is StopReason.TIMEOUT
    assert task.verdict is not None and task.verdict.label == "aligned"


def test_end_once_and_hold_before_finishing() -> None:
    task = in_align(Alignment())
    assert task.end(NS, Stop(StopReason.FORCE_LIMIT, "force"))
    assert not task.end(NS, Stop(StopReason.TIMEOUT, "timeout"))  # the first end stays
    assert task.phase is Phase.ABORT and task.stop is not None
    assert task.stop.reason is StopReason.FORCE_LIMIT
    assert not task.finished(NS + 99_000_000)
    assert task.finished(NS + 100_000_000)
    np.testing.assert_equal(task.phase.ended, True)
