"""The lockstep KRC's cheap per-cycle paths give what the plain rules give, value for value.

The link's fast path for a window full of prompt answers against the window's
own rule, the measurement built from a kept head against the dataclass, and a
lockstep run cycle by cycle against the shared rules it inlines or shortcuts:
the robot state (:func:`robot_state_from_fri`), the applied command
(:func:`applied_from_fri` and the clipped gains), and the arm command the world
gets (:class:`CommandDelay` copying :func:`arm_command_from_fri` of each taken
command), with no delay, the KRC's one cycle and two.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from drivers.base.impedance import clip_cart_stiffness
from drivers.base.types import AppliedCommand, ApplyStatus, CartesianCommand, RobotState
from drivers.description import load_scene
from drivers.fri.command import applied_from_fri, copy_fri_command, robot_state_from_fri
from drivers.fri.emulate.krc import (
    CommandDelay,
    StateMeasurement,
    arm_command_from_fri,
    fri_measurement,
    measurement_head,
    measurement_of,
    state_free_head,
)
from drivers.fri.emulate.lockstep import SimRobot
from drivers.fri.link import ERROR_SOFTWARE_LIMIT, KrcLink, QualityThresholds
from drivers.fri.types import CmdFlags, FriCommand, FriMeasurement, FriQuality, FriState
from drivers.world import ArmCommand, SimWorld

ROOT = Path(__file__).resolve().parent.parent
PAPER = ROOT / "data" / "scenes" / "paper.toml"


class _ReferenceLink(KrcLink):
    """A link that takes every packet by the window's rule (no fast path)."""

    def cycle(self, answered: bool, latency_s: float = 0.0) -> object:  # type: ignore[override]
        return self._account(answered, latency_s)


def _link_view(link: KrcLink) -> tuple[object, ...]:
    w = link.window
    return (link.state, link.quality, link.error, link.answered, link.missed,
            link.consecutive_ok, link.consecutive_miss, link.starts, link.fallbacks,
            w.n, w.i, w.answered.tolist(), w.latency.tolist(), w.rates())


@pytest.mark.parametrize("seed", range(6))
def test_link_fast_path_equals_the_window_rule(seed: int) -> None:
    rng = np.random.default_rng(seed)
    kw = dict(start_cycles=int(rng.choice([0, 5, 100])),
              max_consecutive_misses=int(rng.integers(1, 6)),
              timing=bool(seed % 2),
              thresholds=QualityThresholds(bad_miss=float(rng.choice([0.25, -0.1]))))
    fast, ref = KrcLink(0.005, **kw), _ReferenceLink(0.005, **kw)  # type: ignore[arg-type]
    miss_p = float(rng.choice([0.0, 0.01, 0.2]))
    for _ in range(600):
        answered = bool(rng.random() >= miss_p)
        latency = 0.0 if rng.random() < 0.95 or not kw["timing"] else float(rng.random() * 0.004)
        assert fast.cycle(answered, latency) is ref.cycle(answered, latency)
        u = rng.random()
        if u < 0.005:
            assert fast.fault(ERROR_SOFTWARE_LIMIT & 0x3) is ref.fault(ERROR_SOFTWARE_LIMIT & 0x3)
        elif u < 0.02:
            fast.acknowledge()
            ref.acknowledge()
        assert _link_view(fast) == _link_view(ref)


def test_measurement_from_a_head_equals_the_dataclass_with_the_link_fields() -> None:
    world = SimWorld(load_scene(PAPER), seed=3)
    world.step(None)
    s = world.last_state
    rates = (0.97, 0.0012, 0.0003, 0.03)
    head = measurement_head(0.005, FriState.MON, FriQuality.OK, 0x05, rates, 7)
    m = measurement_of(head, s)
    ref = fri_measurement(s, 0.005, FriState.MON, FriQuality.OK, 0x05)
    ref.answer_rate, ref.latency_s, ref.jitter_s, ref.miss_rate = rates
    ref.miss_counter = 7
    assert m == ref
    assert list(vars(m)) == list(vars(ref))
    assert m.link_events is not measurement_of(head, s).link_events  # each its own


def test_a_state_measurement_reads_the_state_once_and_equals_measurement_of() -> None:
    """A :class:`StateMeasurement` holds the head's fields only until one of the state's
    is read; then it holds every field, each the value (the very object) that
    :func:`measurement_of` gives, and a field set before keeps its value."""
    world = SimWorld(load_scene(PAPER), seed=4)
    for _ in range(3):
        world.step(None)
    s = world.last_state
    s.resolve()
    head = measurement_head(0.005, FriState.CMD, FriQuality.PERFECT, 0, (1.0, 0.0, 0.0, 0.0), 2)
    ref = measurement_of(head, s)
    lazy: StateMeasurement = object.__new__(StateMeasurement)
    lazy.__dict__ = {**state_free_head(head), "link_events": []}
    lazy.arm_state = s
    assert not set(vars(lazy)) & {"seq", "msr_jnt_pos", "jacobian", "warning"}
    assert (lazy.state, lazy.quality, lazy.miss_counter) == (FriState.CMD, FriQuality.PERFECT, 2)
    assert "seq" not in vars(lazy)  # (the link's fields read nothing of the state)
    lazy.time_ns = 7
    assert lazy.jacobian is ref.jacobian
    assert lazy.time_ns == 7 and lazy.seq == ref.seq == s.cycle
    lazy.time_ns = ref.time_ns
    assert lazy == ref and ref == lazy
    assert sorted(vars(lazy)) == sorted(vars(ref))
    for name, value in vars(ref).items():
        assert getattr(lazy, name) is value or getattr(lazy, name) == value, name
    assert StateMeasurement.seq == FriMeasurement.seq  # (the class keeps the defaults)
    other = measurement_of(head, s)
    other.seq += 1
    assert lazy != other and other != lazy


def _state_view(state: RobotState) -> list[tuple[str, object]]:
    out: list[tuple[str, object]] = []
    for name, value in vars(state).items():
        if name == "link":
            out += [(f"link.{k}", v) for k, v in vars(value).items()]
        else:
            out.append((name, value))
    return out


def _reference_applied(robot: SimRobot, fri: FriCommand, status: ApplyStatus) -> AppliedCommand:
    """What send() returns by the plain rules: applied_from_fri, then the clipped gains."""
    ref = applied_from_fri(fri, status, AppliedCommand())
    if int(fri.flags) & int(CmdFlags.CARTSTIFF):
        mx = robot.world.scene.controller.cart_stiffness_max
        k, clipped = clip_cart_stiffness(fri.cart_stiffness, mx[0], mx[1])
        d = np.clip(fri.cart_damping, 0.0, 1.0)
        if clipped or np.any(d != fri.cart_damping):
            ref.status |= ApplyStatus.CLIPPED
            ref.command.stiffness_npm_nmprad[...] = k
            ref.command.damping_ratio[...] = d
    return ref


def _arm_view(arm: ArmCommand | None) -> list[tuple[str, object]] | None:
    if arm is None:
        return None
    return [(f.name, None if (v := getattr(arm, f.name)) is None
             else v.tolist() if isinstance(v, np.ndarray) else v)
            for f in dataclasses.fields(arm)]


@pytest.mark.parametrize("delay", [0, 1, 2])
def test_lockstep_cycles_equal_the_plain_rules(delay: int) -> None:
    """Measurements, robot states, applied commands and the world's arm commands, cycle
    by cycle, through MON (mirrors), the start, CMD, held cycles, changing and clipped
    gains and unanswered cycles."""
    scene = load_scene(PAPER, [f"fri.command_delay_cycles={delay}"])
    world = SimWorld(scene, seed=1)
    robot = SimRobot(world, start_cycles=100)
    given: list[list[tuple[str, object]] | None] = []
    advance = world.advance

    def capture(arm: ArmCommand | None = None) -> None:
        given.append(_arm_view(arm))  # (before the world latches it)
        advance(arm)

    world.advance = capture  # type: ignore[method-assign,assignment]
    ref_delay = CommandDelay(delay)
    rng = np.random.default_rng(delay)
    robot.connect()
    states = robot.measurements()
    state = next(states)
    pose = state.tcp_pose_m.copy()
    commanded = 0
    for i in range(260):
        m = robot.measurement
        link = robot.link
        ref_m = fri_measurement(world.last_state, world.cycle_s, link.state, link.quality,
                                link.error)
        ref_m.answer_rate, ref_m.latency_s, ref_m.jitter_s, ref_m.miss_rate = link.rates()
        ref_m.miss_counter = link.missed
        assert m == ref_m and ref_m == m, i
        assert sorted(vars(m)) == sorted(vars(ref_m)), i  # (read: every field filled)
        ref_state = robot_state_from_fri(m)
        ref_state.truth = world.last_state.truth
        assert _state_view(state) == _state_view(ref_state), i
        u = rng.random()
        taken: FriCommand | None = None
        if i < 150 or i % 37:  # (cycles after 150 without an answer, now and then)
            cmd = None if u < 0.1 else CartesianCommand(
                pose_m=pose + np.pad(rng.normal(0, 1e-4, (3, 1)), ((0, 1), (3, 0))),
                stiffness_npm_nmprad=np.array([2000.0, 2000.0, 2000.0, 200.0, 200.0, 200.0])
                * (3.0 if u > 0.9 else 1.0),  # beyond the arm's limits: clipped
                damping_ratio=np.full(6, 0.7 if u < 0.8 else 1.2),
                wrench_n_nm=rng.normal(0, 1.0, 6))
            applied = robot.send(cmd)
            fri = applied.extras
            assert isinstance(fri, FriCommand)
            ref = _reference_applied(robot, fri, applied.status & ~ApplyStatus.CLIPPED)
            assert applied.status == ref.status, i
            for name in ("pose_m", "stiffness_npm_nmprad", "damping_ratio", "wrench_n_nm"):
                assert getattr(applied.command, name).tolist() == \
                    getattr(ref.command, name).tolist(), (i, name)
            taken = FriCommand()
            copy_fri_command(fri, taken)
        mode = world.mode
        was_cmd = robot.link.state == FriState.CMD
        given.clear()
        state = next(states)  # the next cycle
        now_cmd = robot.link.state == FriState.CMD
        assert len(given) == 1
        if was_cmd and not now_cmd:  # the KRC's own stop, what was in flight dropped
            ref_delay.clear()
            continue
        take = taken is not None and now_cmd
        commanded += take
        expect = ref_delay.push(arm_command_from_fri(taken, mode) if taken is not None and take
                                else None)[0]
        assert given[0] == _arm_view(expect), i
    assert commanded > 100  # (the run did command)


def test_each_connect_reports_the_link_up_and_state_changes_once() -> None:
    """The link watch runs only when the link changed: a new connect is a change, and a
    start (MON -> CMD) is reported in the cycle it happens, once."""
    world = SimWorld(load_scene(PAPER), seed=2)
    robot = SimRobot(world, start_cycles=3)
    for _ in range(2):
        robot.connect()
        states = robot.measurements()
        events = []
        for _ in range(110):
            state = next(states)
            assert state.extras is not None
            events += [e[3] for e in state.extras.take_events()]
            robot.send(None)
        assert [e.split(" (")[0] for e in events] == [
            "FRI link up: state MON, quality BAD", "FRI quality BAD -> OK",
            "FRI state MON -> CMD", "FRI quality OK -> PERFECT"]
