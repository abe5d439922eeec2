from __future__ import annotations

import numpy as np
import pytest

from drivers.base import Command, FtSamples, Measurement
from drivers.errors import DriverTimeoutError, LinkLostError, NotConnectedError
from drivers.mock import MockFtSensor, MockRobot


def _script(n: int) -> list[Measurement]:
    return [Measurement(seq=i, time_ns=i * 5_000_000) for i in range(n)]


def test_replays_and_records_one_command_per_cycle() -> None:
    robot = MockRobot(_script(3))
    seen = []
    with robot:
        for m in robot.measurements():
            seen.append(m.seq)
            if m.seq != 1:
                robot.send(Command(add_tcp_ft=np.full(6, float(m.seq))))
    assert seen == [0, 1, 2]
    assert len(robot.sent) == 3
    assert robot.sent[1] is None  # cycle 1 got no answer
    assert robot.sent[2] is not None and robot.sent[2].add_tcp_ft[0] == 2.0
    assert not robot.connected


def test_not_connected() -> None:
    robot = MockRobot(_script(1))
    with pytest.raises(NotConnectedError):
        next(robot.measurements())
    with pytest.raises(NotConnectedError):
        robot.send(Command())


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
