from __future__ import annotations

import numpy as np
import pytest

from drivers.base import ApplyStatus, CartesianCommand, FtSamples, LinkHealth, RobotState
from drivers.base.types import Extras
from drivers.errors import DriverTimeoutError, LinkLostError, NotConnectedError
from drivers.mock import MockFtSensor, MockRobot, NoisyFtSensor, stationary_robot


class Tag(Extras):
    def __init__(self, k: int) -> None:
        self.k = k


def _script(n: int) -> list[RobotState]:
    return [RobotState(time_ns=i * 5_000_000, link=LinkHealth(cycle=i), extras=Tag(i))
            for i in range(n)]


def test_replays_and_records_a_copy_of_one_command_per_cycle() -> None:
    robot = MockRobot(_script(3))
    seen = []
    cmd = CartesianCommand()
    with robot:
        for s in robot.measurements():
            assert isinstance(s.extras, Tag)
            seen.append(s.extras.k)
            if s.link.cycle != 1:
                cmd.wrench_n_nm[:] = float(s.link.cycle)
                applied = robot.send(cmd)
                assert applied.status == ApplyStatus.APPLIED
                assert applied.command is not cmd
    cmd.wrench_n_nm[:] = 99.0  # the caller reuses its command: the records must not change
    assert seen == [0, 1, 2]
    assert len(robot.sent) == 3 and robot.answered == [True, False, True]
    assert robot.sent[1] is None  # cycle 1 got no answer
    assert robot.sent[0] is not None and robot.sent[0].wrench_n_nm[0] == 0.0
    assert robot.sent[2] is not None and robot.sent[2].wrench_n_nm[0] == 2.0
    assert not robot.connected


def test_hold_is_recorded_as_none_and_answered() -> None:
    robot = MockRobot(_script(2))
    with robot:
        for _ in robot.measurements():
            assert robot.send(None).status == ApplyStatus.HELD
    assert robot.sent == [None, None] and robot.answered == [True, True]


def test_not_connected() -> None:
    robot = MockRobot(_script(1))
    with pytest.raises(NotConnectedError, match="mock robot"):
        next(robot.measurements())
    with pytest.raises(NotConnectedError, match="mock robot"):
        robot.send(CartesianCommand())


@pytest.mark.parametrize(("kind", "error"), [("timeout", DriverTimeoutError),
                                             ("link_lost", LinkLostError)])
def test_scripted_failures(kind: str, error: type[Exception]) -> None:
    robot = MockRobot(_script(5), fail_after=2, fail_with=kind)
    robot.connect()
    it = robot.measurements()
    next(it)
    next(it)
    with pytest.raises(error):
        next(it)


def test_stationary_robot() -> None:
    pose = np.eye(4)
    pose[:3, 3] = [0.5, 0.1, 0.4]
    robot = stationary_robot(4, cycle_s=0.002, tcp_pose_m=pose)
    with robot:
        states = list(robot.measurements())
    assert [s.time_ns for s in states] == [0, 2_000_000, 4_000_000, 6_000_000]
    assert [s.link.cycle for s in states] == [0, 1, 2, 3]
    assert all(s.link.commanding and s.link.cycle_s == 0.002 for s in states)
    assert states[0].tcp_pose_m is not states[1].tcp_pose_m
    np.testing.assert_array_equal(states[3].tcp_pose_m, pose)


def test_mock_sensor_blocks_then_empty() -> None:
    block = FtSamples(time_ns=np.array([1]), seq=np.array([0]), wrench=np.zeros((1, 6)),
                      status=np.zeros(1, dtype=np.uint32))
    s = MockFtSensor([block])
    with pytest.raises(NotConnectedError):
        s.samples()
    with s:
        assert len(s.samples()) == 1
        assert len(s.samples()) == 0
        s.tare()
    assert s.tared == 1 and not s.running


def test_noisy_sensor_rate_noise_and_tare() -> None:
    now = [0]
    w = (1.0, -2.0, 3.0, 0.1, 0.0, 0.0)
    a = NoisyFtSensor(w, noise_std=(0.05, 0.001), rate_hz=1000.0, seed=4, clock=lambda: now[0])
    b = NoisyFtSensor(w, noise_std=(0.05, 0.001), rate_hz=1000.0, seed=4, clock=lambda: now[0])
    with a, b:
        first = a.samples()
        assert len(first) == 1 and first.time_ns.tolist() == [0]
        b.samples()
        now[0] = 1_000_000_000
        s = a.samples()
        assert len(s) == 1000
        assert s.seq.tolist() == list(range(1, 1001))
        np.testing.assert_array_equal(np.diff(s.time_ns), 1_000_000)
        np.testing.assert_allclose(s.wrench.mean(axis=0), w, atol=0.01)
        assert s.wrench[:, 0].std() == pytest.approx(0.05, rel=0.1)
        assert len(a.samples()) == 0  # nothing new is due
        np.testing.assert_array_equal(b.samples().wrench, s.wrench)  # same seed, same noise
        a.tare()
        now[0] = 2_000_000_000
        np.testing.assert_allclose(a.samples().wrench.mean(axis=0), 0.0, atol=0.01)
    with pytest.raises(NotConnectedError, match="mock F/T sensor"):
        a.samples()
