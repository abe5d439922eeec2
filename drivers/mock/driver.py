"""The ``mock`` back-ends: replay scripted robot states and F/T samples, record commands.

:class:`MockRobot` yields a script of :class:`~drivers.base.types.RobotState`
(any ``extras``), keeps a copy of every command it is sent, and answers with
an :class:`~drivers.base.types.AppliedCommand` (the command itself, APPLIED;
``None`` is HELD at the state's pose). :func:`stationary_robot` scripts a
robot that stands still; :class:`MockFtSensor` replays F/T blocks and
:class:`NoisyFtSensor` streams a constant wrench plus seeded noise.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator, Sequence

import numpy as np

from drivers.base.guards import requires_open
from drivers.base.interfaces import FlagStream, ForceTorqueSensor, RobotDriver
from drivers.base.types import (
    NS_PER_S,
    AppliedCommand,
    ApplyStatus,
    CartesianCommand,
    FtSamples,
    LinkHealth,
    RobotState,
)
from drivers.errors import DriverTimeoutError, LinkLostError

__all__ = ["MockFtSensor", "MockRobot", "NoisyFtSensor", "stationary_robot"]


class MockRobot(RobotDriver):
    """Yields ``script`` one state per cycle; a copy of every ``send`` is kept in :attr:`sent`.

    ``sent[i]`` is what cycle ``i`` was answered with (``None``: held, or not
    answered at all; :attr:`answered` tells the two apart).

    Args:
        script: states to replay, in order (yielded as they are).
        fail_after: raise ``fail_with`` instead of yielding state number
            ``fail_after`` (to test error paths).
        fail_with: ``"timeout"`` or ``"link_lost"``.
    """

    def __init__(
        self,
        script: Sequence[RobotState],
        fail_after: int | None = None,
        fail_with: str = "timeout",
    ) -> None:
        if fail_with not in ("timeout", "link_lost"):
            raise ValueError("fail_with must be 'timeout' or 'link_lost'")
        self.script = list(script)
        self.fail_after = fail_after
        self.fail_with = fail_with
        self.sent: list[CartesianCommand | None] = []
        self.answered: list[bool] = []
        self._open = False
        self._current: RobotState | None = None
        self._pending: CartesianCommand | None = None
        self._was_answered = False

    def connect(self) -> None:
        self._open = True

    def close(self) -> None:
        self._open = False

    @property
    def connected(self) -> bool:
        return self._open

    def now_ns(self) -> int | None:
        """The time of the current state (``None`` before the first)."""
        return None if self._current is None else self._current.time_ns

    @requires_open("mock robot")
    def measurements(self) -> Iterator[RobotState]:
        return self._measurements()

    def _flush(self) -> None:
        self.sent.append(self._pending)
        self.answered.append(self._was_answered)
        self._pending = None
        self._was_answered = False

    def _measurements(self) -> Iterator[RobotState]:
        for i, state in enumerate(self.script):
            if not self._open:
                return
            if self.fail_after is not None and i >= self.fail_after:
                if self.fail_with == "timeout":
                    raise DriverTimeoutError(f"mock robot: no state for cycle {i}")
                raise LinkLostError(f"mock robot: link lost at cycle {i}")
            if i > 0:
                self._flush()
            self._current = state
            yield state
        if self._open and self.script:
            self._flush()

    @requires_open("mock robot")
    def send(self, command: CartesianCommand | None) -> AppliedCommand:
        """Record a copy of ``command``; the last ``send`` of a cycle is its answer."""
        self._was_answered = True
        if command is None:
            self._pending = None
            held = CartesianCommand()
            if self._current is not None:
                held.pose_m[:] = self._current.tcp_pose_m
            return AppliedCommand(held, ApplyStatus.HELD)
        self._pending = command.copy()
        return AppliedCommand(command.copy(), ApplyStatus.APPLIED)


def stationary_robot(
    cycles: int,
    cycle_s: float = 0.005,
    tcp_pose_m: np.ndarray | None = None,
    joint_pos_rad: Sequence[float] = (0.0,) * 7,
    commanding: bool = True,
) -> MockRobot:
    """A robot that stands still for ``cycles`` cycles (each state its own arrays)."""
    pose = np.eye(4) if tcp_pose_m is None else np.asarray(tcp_pose_m, dtype=np.float64)
    q = np.asarray(joint_pos_rad, dtype=np.float64)
    cycle_ns = round(cycle_s * NS_PER_S)
    script = [
        RobotState(
            time_ns=i * cycle_ns,
            tcp_pose_m=pose.copy(),
            joint_pos_rad=q.copy(),
            link=LinkHealth(commanding=commanding, healthy=True, cycle=i, cycle_s=cycle_s),
            tcp_twist_mps_radps=np.zeros(6),
        )
        for i in range(cycles)
    ]
    return MockRobot(script)


class MockFtSensor(FlagStream, ForceTorqueSensor):
    """Returns one scripted :class:`FtSamples` block per ``samples()`` call, then empty blocks."""

    def __init__(self, script: Sequence[FtSamples]) -> None:
        self.script = list(script)
        self._i = 0
        self.tared = 0

    @requires_open("mock F/T sensor")
    def samples(self) -> FtSamples:
        if self._i >= len(self.script):
            return FtSamples()
        out = self.script[self._i]
        self._i += 1
        return out

    @requires_open("mock F/T sensor")
    def tare(self) -> None:
        self.tared += 1


class NoisyFtSensor(FlagStream, ForceTorqueSensor):
    """A constant wrench plus seeded white noise, ``rate_hz`` samples per second of a clock.

    Each ``samples()`` call returns the samples due on ``clock`` since the
    last call (samples at ``k / rate_hz`` up to the clock's time); a software
    bias (``tare``) subtracts the constant wrench.

    Args:
        wrench_n_nm: the constant wrench [N, N m].
        noise_std: white noise standard deviation (force [N], torque [N m]).
        rate_hz: sample rate.
        seed: the noise generator's seed.
        clock: the time [ns] the samples are due by (e.g. the robot's cycle
            time; ``None`` from it: nothing due yet); default: wall time since
            ``start``.
    """

    def __init__(
        self,
        wrench_n_nm: Sequence[float] = (0.0,) * 6,
        noise_std: tuple[float, float] = (0.03, 0.0005),
        rate_hz: float = 1000.0,
        seed: int = 0,
        clock: Callable[[], int | None] | None = None,
    ) -> None:
        if not rate_hz > 0.0:
            raise ValueError(f"rate_hz must be positive, got {rate_hz}")
        self.wrench = np.asarray(wrench_n_nm, dtype=np.float64).copy()
        self.noise = np.array([noise_std[0]] * 3 + [noise_std[1]] * 3)
        self.period_ns = round(NS_PER_S / rate_hz)
        self.rng = np.random.default_rng(seed)
        self.offset = np.zeros(6)
        self._next_seq = 0
        self._t0 = 0
        self.clock = clock if clock is not None else self._wall_ns
        self.tared = 0

    def _wall_ns(self) -> int:
        return time.monotonic_ns() - self._t0

    def start(self) -> None:
        self._t0 = time.monotonic_ns()
        super().start()

    @requires_open("mock F/T sensor")
    def samples(self) -> FtSamples:
        now = self.clock()
        due = 0 if now is None else int(now) // self.period_ns + 1
        n = max(0, due - self._next_seq)
        seq = np.arange(self._next_seq, self._next_seq + n, dtype=np.int64)
        self._next_seq += n
        w = self.wrench - self.offset + self.rng.standard_normal((n, 6)) * self.noise
        return FtSamples(time_ns=seq * self.period_ns, seq=seq, wrench=w,
                         status=np.zeros(n, dtype=np.uint32))

    @requires_open("mock F/T sensor")
    def tare(self) -> None:
        self.offset = self.wrench.copy()
        self.tared += 1
