"""The in-process sim robot (drivers.fri.emulate.lockstep) and sensor, driven like the loop does."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from drivers.base import ApplyStatus, CartesianCommand, ForceTorqueSensor, RobotDriver, RobotState
from drivers.errors import ConfigError, InvalidCommandError, NotConnectedError
from drivers.fri.emulate.lockstep import SimRobot, open_sim
from drivers.fri.types import FriCommand, FriMeasurement, FriQuality, FriState
from drivers.world import SimWorld

PAPER_K = np.array([5000.0, 0.0, 0.0, 0.0, 300.0, 300.0])
PAPER_D = np.array([0.7, 0.0, 0.0, 0.0, 0.7, 0.7])


def push(state: RobotState, fz: float) -> CartesianCommand:
    """Hold the pose with the paper's impedance, plus a wrench along the tool's Z."""
    return CartesianCommand(
        pose_m=state.tcp_pose_m.copy(),
        stiffness_npm_nmprad=PAPER_K.copy(),
        damping_ratio=PAPER_D.copy(),
        wrench_n_nm=np.array([0.0, 0.0, fz, 0.0, 0.0, 0.0]),
    )


def fri(state: RobotState) -> FriMeasurement:
    assert isinstance(state.extras, FriMeasurement)
    return state.extras


def test_runner_loop_lockstep(paper_scene_path: Path) -> None:
    robot, sensor = open_sim(paper_scene_path, max_cycles=20, start_cycles=0)
    assert isinstance(robot, RobotDriver) and isinstance(sensor, ForceTorqueSensor)
    times, n_ft, ft_t = [], [], []
    cmd: CartesianCommand | None = None
    with robot, sensor:
        for s in robot.measurements():
            ft = sensor.samples()
            times.append(s.time_ns)
            n_ft.append(len(ft))
            ft_t.extend(ft.time_ns.tolist())
            assert s.link.commanding and s.link.healthy and s.link.cycle_s == 0.005
            assert fri(s).state == FriState.CMD and fri(s).quality == FriQuality.PERFECT
            cmd = cmd or push(s, 2.0)
            applied = robot.send(cmd)
            assert applied.status == ApplyStatus.APPLIED
            assert isinstance(applied.extras, FriCommand)
    assert times == [i * 5_000_000 for i in range(20)]
    assert n_ft == [0] + [5] * 19  # 1 kHz samples, 5 per 5 ms cycle
    assert np.all(np.diff(ft_t) == 1_000_000)
    # the push was applied: the TCP moved along +Z (world +x)
    assert robot.world.last_state.truth.tcp_twist[2] > 0.0


def test_state_carries_truth_and_the_fri_measurement(paper_scene_path: Path) -> None:
    robot, _ = open_sim(paper_scene_path, max_cycles=3, start_cycles=0)
    with robot:
        for s in robot.measurements():
            m = fri(s)
            assert s.truth is robot.world.last_state.truth
            assert s.tcp_pose_m is m.msr_cart_pos and s.joint_pos_rad is m.msr_jnt_pos
            assert s.ext_wrench_n_nm is m.est_ext_tcp_ft
            assert s.link.cycle == m.seq == robot.world.cycle
            robot.send(None)


def test_unanswered_cycles_repeat_the_last_command_then_fall_back(paper_scene_path: Path) -> None:
    robot, _ = open_sim(paper_scene_path, max_cycles=12, start_cycles=0)
    states, speed = [], []
    with robot:
        for s in robot.measurements():
            states.append(fri(s).state)
            speed.append(float(s.truth.tcp_twist[2]) if s.truth else 0.0)
            if s.link.cycle == 0:
                robot.send(push(s, 3.0))
    # cycle 0 answered; misses at 1..5: the 5th miss in a row leaves CMD (with a stop)
    assert states[:6] == [FriState.CMD] * 6
    assert states[6:] == [FriState.MON] * 6
    d = robot.delay.cycles  # the answer to cycle 0 acts from cycle d (the KRC's timing)
    assert d >= 1 and speed[:1 + d] == [0.0] * (1 + d)
    assert 0.0 < speed[1 + d] < speed[3] < speed[5]  # the push held through the misses


def test_hold_and_mirror_status(paper_scene_path: Path) -> None:
    robot, _ = open_sim(paper_scene_path, max_cycles=2)
    with robot:
        s = next(robot.measurements())
        assert not s.link.commanding and s.link.healthy
        assert fri(s).state == FriState.MON and fri(s).quality == FriQuality.BAD
        assert robot.send(None).status == ApplyStatus.HELD
        applied = robot.send(push(s, 1.0))
        assert applied.status == ApplyStatus.MIRRORED
        np.testing.assert_array_equal(applied.command.pose_m, fri(s).cmd_cart_pos)


def test_clipped_stiffness_is_reported(paper_scene_path: Path) -> None:
    robot, _ = open_sim(paper_scene_path, max_cycles=3, start_cycles=0)
    with robot:
        for s in robot.measurements():
            cmd = push(s, 0.0)
            cmd.stiffness_npm_nmprad[0] = 9000.0
            applied = robot.send(cmd)
            assert applied.status == ApplyStatus.CLIPPED
            assert applied.command.stiffness_npm_nmprad[0] == 5000.0
            assert cmd.stiffness_npm_nmprad[0] == 9000.0  # the caller's command is untouched
            if s.link.cycle == 1 + robot.delay.cycles:  # the first command acts then
                assert fri(s).warning & 0x0001  # the world clipped it too


def test_send_copies_the_command(paper_scene_path: Path) -> None:
    robot, _ = open_sim(paper_scene_path, max_cycles=40, start_cycles=0)
    with robot:
        cmd: CartesianCommand | None = None
        for s in robot.measurements():
            if cmd is None:
                cmd = push(s, 0.0)
            cmd.wrench_n_nm[2] = 3.0
            robot.send(cmd)
            cmd.wrench_n_nm[2] = 0.0  # changed after send: the robot must not see it
    assert robot.world.last_state.truth.tcp_twist[2] > 0.01


def test_non_finite_command_is_refused(paper_scene_path: Path) -> None:
    robot, _ = open_sim(paper_scene_path, max_cycles=3, start_cycles=0)
    with robot, pytest.raises(InvalidCommandError):
        for s in robot.measurements():
            robot.send(push(s, float("nan")))


def test_not_started_errors(paper_scene_path: Path) -> None:
    robot, sensor = open_sim(paper_scene_path, max_cycles=1)
    with pytest.raises(NotConnectedError, match="sim robot"):
        next(robot.measurements())
    with pytest.raises(NotConnectedError, match="sim robot"):
        robot.send(None)
    with pytest.raises(NotConnectedError, match="sim F/T sensor"):
        sensor.samples()
    with pytest.raises(NotConnectedError, match="sim F/T sensor"):
        sensor.tare()


def test_scene_override_and_error(paper_scene_path: Path) -> None:
    robot, _ = open_sim(paper_scene_path, overrides=["fri.cycle=0.002"])
    assert robot.world.substeps == 2
    with pytest.raises(ConfigError, match=r"nope\.toml"):
        open_sim(paper_scene_path.parent / "nope.toml")


def test_tare_zeroes_reading(paper_scene_path: Path) -> None:
    robot, sensor = open_sim(paper_scene_path, max_cycles=30)
    with robot, sensor:
        for s in robot.measurements():
            if s.link.cycle == 10:
                sensor.tare()
            ft = sensor.samples()
            if s.link.cycle > 12:
                assert np.all(np.abs(ft.wrench[:, :3]) < 0.25)
            robot.send(None)


def test_world_is_shared_by_the_pair(paper_scene_path: Path) -> None:
    robot, sensor = open_sim(paper_scene_path)
    assert isinstance(robot, SimRobot)
    assert isinstance(robot.world, SimWorld) and sensor.world is robot.world


def test_link_starts_in_monitor_mode_like_fristart(paper_scene_path: Path) -> None:
    """MON (commands ignored) until 100 consecutive answers, then CMD from that command on."""
    robot, _ = open_sim(paper_scene_path, max_cycles=200)
    states, quality, speed = [], [], []
    with robot:
        for i, s in enumerate(robot.measurements()):
            states.append(fri(s).state)
            quality.append(fri(s).quality)
            assert s.truth is not None
            speed.append(abs(float(s.truth.tcp_twist[2])))
            if i != 50:  # one unanswered cycle restarts the count
                robot.send(push(s, 2.0))
    # answers 0..49, a miss at 50, then 100 answers 51..150: the command of cycle 150
    # is the first one applied, so measurement 151 is the first in CMD
    assert states.index(FriState.CMD) == 151
    assert all(s == FriState.MON for s in states[:151])
    assert quality[0] == FriQuality.BAD  # nothing rated yet
    assert set(quality[1:151]) <= {FriQuality.OK, FriQuality.BAD}  # rated, window not full
    assert set(quality[151:]) == {FriQuality.PERFECT}
    assert max(speed[:151]) < 1e-6  # nothing was applied in MON
    assert speed[-1] > 1e-3  # the push acts once in CMD
