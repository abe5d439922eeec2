"""The sim back-ends driven the way the runner drives them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from drivers.base import CmdFlags, Command, ForceTorqueSensor, RobotDriver
from drivers.errors import ConfigError, NotConnectedError
from drivers.sim import SimWorld, open_sim


def test_runner_loop_lockstep(paper_scene_path: Path) -> None:
    robot, sensor = open_sim(paper_scene_path, max_cycles=20)
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
    robot, _ = open_sim(paper_scene_path, max_cycles=40)
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
