"""The sim back-ends driven the way the runner drives them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from drivers.base import CmdFlags, Command, ForceTorqueSensor, RobotDriver
from drivers.base.types import FriState
from drivers.errors import ConfigError, NotConnectedError
from drivers.sim import SimWorld, open_sim


def test_runner_loop_lockstep(paper_scene_path: Path) -> None:
    robot, sensor = open_sim(paper_scene_path, max_cycles=20, start_cycles=0)
    assert isinstance(robot, RobotDriver) and isinstance(sensor, ForceTorqueSensor)
    times, n_ft, ft_t = [], [], []
    with robot, sensor:
        for m in robot.measurements():
            ft = sensor.samples()
            times.append(m.time_ns)
            n_ft.append(len(ft))
            ft_t.extend(ft.time_ns.tolist())
            robot.send(Command(flags=CmdFlags.TCPFT, add_tcp_ft=np.array([0, 0, 2.0, 0, 0, 0])))
    assert times == [i * 5_000_000 for i in range(20)]
    assert n_ft == [0] + [5] * 19  # 1 kHz samples, 5 per 5 ms cycle
    assert np.all(np.diff(ft_t) == 1_000_000)
    # the push was applied: the TCP moved along +Z (world +x)
    assert robot.world.last_measurement.truth is not None
    assert robot.world.last_measurement.truth.tcp_twist[2] > 0.0


def test_unanswered_cycle_repeats_last_command(paper_scene_path: Path) -> None:
    robot, _ = open_sim(paper_scene_path, max_cycles=40, start_cycles=0)
    push = Command(flags=CmdFlags.TCPFT, add_tcp_ft=np.array([0, 0, 3.0, 0, 0, 0]))
    with robot:
        for m in robot.measurements():
            if m.seq == 0:
                robot.send(push)
    assert robot.world.last_measurement.truth is not None
    assert robot.world.last_measurement.truth.tcp_twist[2] > 0.01


def test_not_started_errors(paper_scene_path: Path) -> None:
    robot, sensor = open_sim(paper_scene_path, max_cycles=1)
    with pytest.raises(NotConnectedError):
        next(robot.measurements())
    with pytest.raises(NotConnectedError):
        sensor.samples()


def test_scene_override_and_error(paper_scene_path: Path) -> None:
    robot, _ = open_sim(paper_scene_path, overrides=["fri.cycle=0.002"])
    assert robot.world.substeps == 2
    with pytest.raises(ConfigError, match=r"nope\.toml"):
        open_sim(paper_scene_path.parent / "nope.toml")


def test_tare_zeroes_reading(paper_scene_path: Path) -> None:
    robot, sensor = open_sim(paper_scene_path, max_cycles=30)
    with robot, sensor:
        for m in robot.measurements():
            if m.seq == 10:
                sensor.tare()
            ft = sensor.samples()
            if m.seq > 12:
                assert np.all(np.abs(ft.wrench[:, :3]) < 0.25)


def test_world_is_shared_by_the_pair(paper_scene_path: Path) -> None:
    robot, sensor = open_sim(paper_scene_path)
    assert isinstance(robot.world, SimWorld) and sensor.world is robot.world


def test_link_starts_in_monitor_mode_like_fristart(paper_scene_path: Path) -> None:
    """MON (commands ignored) until 100 consecutive answers, then CMD from that command on."""
    robot, _ = open_sim(paper_scene_path, max_cycles=200)
    push = Command(flags=CmdFlags.TCPFT, add_tcp_ft=np.array([0, 0, 2.0, 0, 0, 0]))
    states, speed = [], []
    with robot:
        for i, m in enumerate(robot.measurements()):
            states.append(m.state)
            assert m.truth is not None
            speed.append(abs(float(m.truth.tcp_twist[2])))
            if i != 50:  # one unanswered cycle restarts the count
                robot.send(push)
    # answers 0..49, a miss at 50, then 100 answers 51..150: the command of cycle 150
    # is the first one applied, so measurement 151 is the first in CMD
    assert states.index(FriState.CMD) == 151
    assert all(s == FriState.MON for s in states[:151])
    assert max(speed[:151]) < 1e-6  # nothing was applied in MON
    assert speed[-1] > 1e-3  # the push acts once in CMD
