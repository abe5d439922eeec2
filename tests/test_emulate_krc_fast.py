"""The emulated KRC's per-cycle shortcuts equal the plain constructions they replace."""

from __future__ import annotations

import copy
import dataclasses
from pathlib import Path

import numpy as np
import pytest

from drivers.base.types import CartesianCommand, LinkHealth, RobotState
from drivers.errors import NotConnectedError
from drivers.fri.command import robot_state_from_fri
from drivers.fri.emulate.krc import DRIVE_TEMPERATURE_C, fri_measurement, fri_warning
from drivers.fri.emulate.lockstep import open_sim
from drivers.fri.types import (
    WARN_POSITION_LIMIT,
    WARN_STIFFNESS_CLIPPED,
    WARN_TORQUE_LIMIT,
    WARN_VELOCITY_LIMIT,
    ControlMode,
    FriMeasurement,
    FriQuality,
    FriState,
)
from drivers.world.arm import ArmMode, ArmState, ArmWarning

SCENE = Path(__file__).resolve().parent.parent / "data" / "scenes" / "paper.toml"


def _state(seed: int) -> ArmState:
    rng = np.random.default_rng(seed)
    s = ArmState(cycle=17 + seed, time_ns=(17 + seed) * 5_000_000, mode=ArmMode.JOINT_IMPEDANCE,
                 warning=ArmWarning.TORQUE_LIMIT | ArmWarning.POSITION_LIMIT)
    for f in dataclasses.fields(ArmState):
        value = getattr(s, f.name)
        if isinstance(value, np.ndarray):
            setattr(s, f.name, rng.normal(size=value.shape))
    return s


def _reference(s: ArmState, cycle_s: float, state: FriState, quality: FriQuality,
               error: int) -> FriMeasurement:
    """The measurement as the dataclass builds it (what fri_measurement did before)."""
    bits = {ArmWarning.STIFFNESS_CLIPPED: WARN_STIFFNESS_CLIPPED,
            ArmWarning.TORQUE_LIMIT: WARN_TORQUE_LIMIT,
            ArmWarning.VELOCITY_LIMIT: WARN_VELOCITY_LIMIT,
            ArmWarning.POSITION_LIMIT: WARN_POSITION_LIMIT}
    return FriMeasurement(
        seq=s.cycle, time_ns=s.time_ns, state=state, quality=quality,
        control=ControlMode.JOINT_IMPEDANCE, msr_sample_time=cycle_s, cmd_sample_time=cycle_s,
        warning=sum(v for k, v in bits.items() if s.warning & k), error=error,
        temperature=np.full(7, DRIVE_TEMPERATURE_C), msr_jnt_pos=s.jnt_pos_rad,
        msr_cart_pos=s.tcp_pose_m, cmd_jnt_pos=s.cmd_jnt_pos_rad,
        cmd_cart_pos=s.cmd_cart_pose_m, msr_jnt_trq=s.jnt_trq_nm,
        est_ext_jnt_trq=s.ext_jnt_trq_nm, est_ext_tcp_ft=s.ext_wrench_n_nm,
        jacobian=s.jacobian, mass_matrix=s.mass_matrix, gravity=s.gravity_nm,
    )


def _assert_same(a: object, b: object) -> None:
    assert type(a) is type(b)
    assert list(vars(a)) == list(vars(b))  # the same fields, in field order
    for name, value in vars(b).items():
        got = getattr(a, name)
        if isinstance(value, np.ndarray):
            assert got.dtype == value.dtype and got.shape == value.shape, name
            assert np.array_equal(got, value), name
        elif dataclasses.is_dataclass(value):
            _assert_same(got, value)
        else:
            assert got == value and type(got) is type(value), name


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fri_measurement_equals_the_dataclass_construction(seed: int) -> None:
    s = _state(seed)
    m = fri_measurement(s, 0.004, FriState.MON, FriQuality.OK, 0x05)
    _assert_same(m, _reference(s, 0.004, FriState.MON, FriQuality.OK, 0x05))
    assert m.jacobian is s.jacobian and m.msr_cart_pos is s.tcp_pose_m  # shared, not copied


def test_fri_measurement_constants_are_read_only_and_events_own() -> None:
    a = fri_measurement(_state(0), 0.005, FriState.CMD, FriQuality.PERFECT)
    b = fri_measurement(_state(1), 0.005, FriState.CMD, FriQuality.PERFECT)
    for name in ("temperature", "cmd_jnt_pos_fri_offset", "cmd_cart_pos_fri_offset",
                 "krl_real", "krl_int"):
        with pytest.raises(ValueError):
            getattr(a, name)[0] = 1
    a.link_events.append((0, "info", "x", "y"))
    assert b.link_events == []
    # a copy owns writable arrays (the remote side fills its own measurements)
    c = copy.deepcopy(a)
    c.temperature[0] = 1.0
    assert a.temperature[0] == DRIVE_TEMPERATURE_C


def test_fri_warning_every_combination() -> None:
    bits = ((ArmWarning.STIFFNESS_CLIPPED, WARN_STIFFNESS_CLIPPED),
            (ArmWarning.TORQUE_LIMIT, WARN_TORQUE_LIMIT),
            (ArmWarning.VELOCITY_LIMIT, WARN_VELOCITY_LIMIT),
            (ArmWarning.POSITION_LIMIT, WARN_POSITION_LIMIT))
    for w in range(64):  # beyond the known bits too
        expected = sum(fri for arm, fri in bits if w & int(arm))
        assert fri_warning(ArmWarning(w & 0xF)) == expected
        assert fri_warning(w) == expected  # type: ignore[arg-type]


def test_robot_state_from_fri_equals_the_dataclass_construction() -> None:
    m = fri_measurement(_state(3), 0.005, FriState.CMD, FriQuality.BAD)
    got = robot_state_from_fri(m)
    ref = RobotState(time_ns=m.time_ns, tcp_pose_m=m.msr_cart_pos, joint_pos_rad=m.msr_jnt_pos,
                     link=LinkHealth(commanding=True, healthy=True, cycle=m.seq, cycle_s=0.005),
                     ext_wrench_n_nm=m.est_ext_tcp_ft, extras=m)
    _assert_same(got, ref)
    again = robot_state_from_fri(m, got)
    assert again is got
    _assert_same(again, ref)


def test_lockstep_measurement_is_the_world_state() -> None:
    robot, _ = open_sim(SCENE, seed=3, start_cycles=0)
    robot.connect()
    it = robot.measurements()
    st = next(it)
    for _ in range(3):
        robot.send(None)
        prev, st = st, next(it)
        assert st.extras is not prev.extras  # a new measurement every cycle
    s = robot.world.last_state
    m = robot.measurement
    link = robot.link
    ref = _reference(s, robot.world.cycle_s, link.state, link.quality, link.error)
    ref.control = m.control
    ref.answer_rate, ref.latency_s, ref.jitter_s, ref.miss_rate = link.rates()
    ref.miss_counter = link.missed
    assert st.extras is m
    # a measurement that reads the world state's fields when first read: once read, the
    # same fields and values (the order of its fields: the link's, then the state's)
    assert isinstance(m, FriMeasurement) and type(m) is not FriMeasurement
    assert m.seq == ref.seq  # (the first read of a state field fills them all)
    view = FriMeasurement()
    view.__dict__ = {name: vars(m)[name] for name in vars(ref)}
    _assert_same(view, ref)


def test_lockstep_send_before_connect_names_the_device() -> None:
    robot, _ = open_sim(SCENE, seed=3, start_cycles=0)
    with pytest.raises(NotConnectedError, match=r"^sim robot: send\(\) before connect/start$"):
        robot.send(None)


def test_lockstep_world_takes_each_cycles_command() -> None:
    """The KRC's arm command is kept while flags, strategy and mode do not change; the
    world still takes the values of every cycle's command (no command delay: each
    answer acts in the cycle it answers)."""
    robot, _ = open_sim(SCENE, seed=3, start_cycles=0, overrides=["fri.command_delay_cycles=0"])
    robot.connect()
    it = robot.measurements()
    st = next(it)
    pose = st.tcp_pose_m.copy()
    cmd = CartesianCommand(pose_m=pose.copy(), stiffness_npm_nmprad=np.full(6, 500.0),
                           damping_ratio=np.full(6, 0.7), wrench_n_nm=np.zeros(6))
    prev_pose = pose
    for i in range(6):
        cmd.pose_m[:3, 3] = pose[:3, 3] + [0.0, 0.0, -0.001 * i]
        if i == 3:
            robot.send(None)  # a mirror in between: other flags
        else:
            robot.send(cmd)
        st = next(it)
        s = robot.world.last_state
        if i == 3:
            assert np.array_equal(s.cmd_cart_pose_m, prev_pose)
        else:
            assert np.array_equal(s.cmd_cart_pose_m, cmd.pose_m)
        prev_pose = s.cmd_cart_pose_m.copy()


def test_sim_ft_sensor_samples_before_start_names_the_device() -> None:
    _, sensor = open_sim(SCENE, seed=3)
    with pytest.raises(NotConnectedError, match=r"^sim F/T sensor: samples\(\) before"):
        sensor.samples()
    sensor.start()
    sensor.samples()
    sensor.stop()
    with pytest.raises(NotConnectedError):
        sensor.samples()
