"""The alignment verdict from a tracker's pose and from the wrench-and-kinematics observer,
on synthetic states (no simulator)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from loop_script import pose_at

from drivers.base.placement import placement
from drivers.base.types import RobotState, TargetObservation
from ffexp.contracts import Phase
from ffexp.estimation import ContactEvent, Estimate
from ffexp.observer import ObserverLimits, WrenchObserver
from ffexp.scenarios.funnel import Alignment, FunnelAlignment
from ffexp.task import Event, Task, Verdict

NS = 1_000_000_000
STEP = 5_000_000


def mouth(insertion_m: float, lateral_m: float, yaw_deg: float, z: float = 0.0) -> np.ndarray:
    """A funnel mouth frame such that the tool of ``pose_at(z)`` has this placement."""
    tool = pose_at(z)
    c, s = math.cos(math.radians(-yaw_deg)), math.sin(math.radians(-yaw_deg))
    m = np.eye(4)
    m[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    # tool tip = mouth + R @ [insertion, lateral, 0]
    m[:3, 3] = tool[:3, 3] - m[:3, :3] @ np.array([insertion_m, lateral_m, 0.0])
    return m


def test_placement_recovers_the_offsets_it_was_built_from() -> None:
    p = placement(pose_at(0.01), mouth(0.025, -0.0015, 1.5, z=0.01))
    assert p.insertion == pytest.approx(0.025)
    assert p.lateral == pytest.approx(-0.0015)
    assert math.degrees(p.yaw) == pytest.approx(1.5)
    assert p.vertical == pytest.approx(0.0, abs=1e-12)


class Clock:
    def __init__(self) -> None:
        self.t = 0


def start(alignment: Alignment, clock: Clock, target: TargetObservation | None) -> Task:
    task = Task(FunnelAlignment(alignment), timeout_s=60.0, stop_hold_s=0.1)
    s = RobotState(tcp_pose_m=pose_at(0.0))
    task.step(0, s, Estimate(tared_now=True, tared=True), target)
    clock.t = STEP
    task.step(clock.t, s, Estimate(tared=True, in_contact=True,
                                   event=ContactEvent("made", clock.t, 0.0)), target)
    assert task.phase is Phase.ALIGN
    return task


def run(task: Task, clock: Clock, seconds: float, target_of: object, *, z: float = 0.0,
        est: Estimate | None = None) -> None:
    e = est if est is not None else Estimate(tared=True, in_contact=True)
    for _ in range(round(seconds / 0.005)):
        clock.t += STEP
        s = RobotState(time_ns=clock.t, tcp_pose_m=pose_at(z))
        target = target_of(clock.t) if callable(target_of) else target_of
        task.step(clock.t, s, e, target)


def seen(m: np.ndarray, valid: bool = True, lag_ns: int = 20_000_000):
    return lambda t: TargetObservation(max(t - lag_ns, 0), np.eye(4), m, valid, "test", t)


@pytest.mark.parametrize(
    ("insertion", "lateral", "yaw", "aligned"),
    [(0.03, 0.001, 1.0, True), (0.03, 0.0025, 1.0, False), (0.03, 0.001, 2.5, False),
     (0.01, 0.0, 0.0, False), (0.021, -0.0019, -1.9, True)],
)
def test_tracker_verdict_uses_the_relative_pose_and_the_protocols_tolerances(
    insertion: float, lateral: float, yaw: float, aligned: bool
) -> None:
    clock = Clock()
    target = seen(mouth(insertion, lateral, yaw))
    task = start(Alignment(hold_s=0.2), clock, target(0))
    run(task, clock, 0.3, target)
    assert task.verdict_source == "tracker"
    assert task.aligned is aligned
    if aligned:
        assert task.verdict is not None and task.verdict.label == "aligned"
        assert task.verdict.source == "tracker"
        assert task.verdict.evidence["lateral_m"] == pytest.approx(lateral)


def test_a_stale_or_lost_tracker_pose_hands_the_verdict_to_the_observer_and_back() -> None:
    clock = Clock()
    good = mouth(0.03, 0.0, 0.0)
    task = start(Alignment(hold_s=0.2, tracker_max_age_s=0.1), clock, seen(good)(0))
    run(task, clock, 0.05, seen(good))
    assert task.verdict_source == "tracker"
    task.notes.clear()
    run(task, clock, 0.3, seen(good, lag_ns=300_000_000))  # stale: 0.3 s old
    assert task.verdict_source == "observer" and not task.aligned
    warnings = [n for n in task.notes if isinstance(n, Event) and n.name == "verdict_source"]
    assert warnings and "stale" in warnings[0].message and warnings[0].level == "WARNING"
    run(task, clock, 0.1, seen(good, valid=False))  # marker lost
    assert task.verdict_source == "observer" and not task.aligned
    run(task, clock, 0.3, seen(good))
    assert task.verdict_source == "tracker" and task.aligned


def test_truth_beats_the_tracker_and_the_verdict_records_both() -> None:
    from funnel_truth import funnel_truth

    clock = Clock()
    task = start(Alignment(hold_s=0.1), clock, None)
    off = funnel_truth(insertion_m=0.03, lateral_m=0.01)
    for _ in range(40):
        clock.t += STEP
        task.step(clock.t, RobotState(time_ns=clock.t, tcp_pose_m=pose_at(0.0), truth=off),
                  Estimate(tared=True, in_contact=True), seen(mouth(0.03, 0.0, 0.0))(clock.t))
    assert task.verdict_source == "truth" and not task.aligned
    task.check_timeout(61 * NS)
    final = [n for n in task.notes if isinstance(n, Verdict) and n.final]
    assert final and final[0].label == "not aligned" and final[0].truth == "not aligned"


LIMITS = ObserverLimits(seated_depth_m=0.03, lateral_force_n=0.3, lateral_torque_nm=0.05,
                        wall_force_ratio=0.5, min_force_n=0.3, lateral_speed_mps=0.002,
                        yaw_rate_radps=0.02, hold_s=1.0, target_mass_kg=12.0)


def drive(obs: WrenchObserver, seconds: float, *, z: float, f_z: float, f_y: float = 0.0,
          t_x: float = 0.0, contact: bool = True, t0: float = 0.0) -> str:
    label = ""
    for k in range(round(seconds / 0.005) + 1):
        label = obs.update(round((t0 + k * 0.005) * NS), z, contact, f_z, f_y, t_x, 0.0, 0.0)
    return label


def test_observer_bounds_the_targets_travel_by_the_impulse_it_was_given() -> None:
    obs = WrenchObserver(LIMITS)
    obs.contact_made(0.0)
    drive(obs, 1.2, z=0.05, f_z=0.3)
    # constant push f from rest: x = f t^2 / (2 m) (semi-implicit Euler: +f dt t / 2m)
    t = 1.2
    bound = obs.state.evidence["target_travel_bound_m"]
    assert bound == pytest.approx(0.3 * t * t / 24.0, rel=0.01)
    assert obs.state.label == "aligned"  # 50 mm advanced, at most 18 mm of it the target's


def test_observer_says_unverified_when_pushing_could_explain_the_advance() -> None:
    obs = WrenchObserver(LIMITS)
    obs.contact_made(0.0)
    assert drive(obs, 1.2, z=0.05, f_z=1.5) == "unverified"


def test_observer_says_not_aligned_when_the_tool_rests_on_one_wall() -> None:
    obs = WrenchObserver(LIMITS)
    obs.contact_made(0.0)
    assert drive(obs, 0.9, z=0.05, f_z=0.5, f_y=0.8) == "unverified"  # not yet sustained
    assert drive(obs, 0.2, z=0.05, f_z=0.5, f_y=0.8, t0=0.905) == "not aligned"
    # the same lateral force under a push three times larger: not a wall's reaction
    obs2 = WrenchObserver(LIMITS)
    obs2.contact_made(0.0)
    assert drive(obs2, 1.5, z=0.05, f_z=2.4, f_y=0.8) == "unverified"


def test_observer_out_of_contact_is_not_aligned_only_behind_the_first_touch() -> None:
    ahead = WrenchObserver(LIMITS)  # seated cones that stopped pushing look like this
    ahead.contact_made(0.0)
    assert drive(ahead, 1.5, z=0.04, f_z=0.0, contact=False) == "unverified"
    behind = WrenchObserver(LIMITS)  # the target only moves away: the funnels are apart
    behind.contact_made(0.0)
    assert drive(behind, 0.5, z=-0.01, f_z=0.0, contact=False) == "unverified"
    assert drive(behind, 0.6, z=-0.01, f_z=0.0, contact=False, t0=0.505) == "not aligned"


def test_the_lost_event_says_why() -> None:
    clock = Clock()
    good = mouth(0.03, 0.0, 0.0)
    task = start(Alignment(), clock, seen(good)(0))
    run(task, clock, 0.05, seen(good))
    task.notes.clear()
    run(task, clock, 0.05, lambda t: TargetObservation(t, np.eye(4), good, False, "camera", t,
                                                       "stream lost: no frames"))
    msgs = [n.message for n in task.notes if isinstance(n, Event) and n.name == "verdict_source"]
    assert msgs == ["the tracker's pose is lost (stream lost: no frames): the observer judges "
                    "until it returns"]


def test_observer_final_label_is_the_current_one_even_if_never_quiet() -> None:
    never = WrenchObserver(LIMITS)
    never.contact_made(0.0)
    drive(never, 2.0, z=0.05, f_z=0.5, f_y=0.2, t_x=0.1)  # always a torque: never quiet
    assert never.final() == "unverified" and never.state.evidence["ever_quiet"] == 0.0
