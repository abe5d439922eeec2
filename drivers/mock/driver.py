"""The ``mock`` back-ends: replay scripted measurements and F/T samples, record commands."""

from __future__ import annotations

from collections.abc import Iterator, Sequence

from drivers.base.interfaces import ForceTorqueSensor, RobotDriver
from drivers.base.types import Command, FtSamples, Measurement
from drivers.errors import DriverTimeoutError, LinkLostError, NotConnectedError


class MockRobot(RobotDriver):
    """Yields ``script`` one measurement per cycle; every ``send`` is kept in :attr:`sent`.

    Args:
        script: measurements to replay, in order.
        fail_after: raise ``fail_with`` instead of yielding measurement number
            ``fail_after`` (to test the runner's error paths).
        fail_with: ``"timeout"`` or ``"link_lost"``.
    """

    def __init__(
        self,
        script: Sequence[Measurement],
        fail_after: int | None = None,
        fail_with: str = "timeout",
    ) -> None:
        if fail_with not in ("timeout", "link_lost"):
            raise ValueError("fail_with must be 'timeout' or 'link_lost'")
        self.script = list(script)
        self.fail_after = fail_after
        self.fail_with = fail_with
        self.sent: list[Command | None] = []
        self._connected = False
        self._pending: Command | None = None

    def connect(self) -> None:
        self._connected = True

    def close(self) -> None:
        self._connected = False

    @property
    def connected(self) -> bool:
        return self._connected

    def measurements(self) -> Iterator[Measurement]:
        if not self._connected:
            raise NotConnectedError("mock robot: measurements() before connect()")
        for i, m in enumerate(self.script):
            if not self._connected:
                return
            if self.fail_after is not None and i >= self.fail_after:
                if self.fail_with == "timeout":
                    raise DriverTimeoutError(f"mock robot: no measurement for cycle {i}")
                raise LinkLostError(f"mock robot: link lost at cycle {i}")
            if i > 0:
                self.sent.append(self._pending)
                self._pending = None
            yield m
        if self._connected and self.script:
            self.sent.append(self._pending)
            self._pending = None

    def send(self, command: Command) -> None:
        if not self._connected:
            raise NotConnectedError("mock robot: send() before connect()")
        self._pending = command


class MockFtSensor(ForceTorqueSensor):
    """Returns one scripted :class:`FtSamples` block per ``samples()`` call, then empty blocks."""

    def __init__(self, script: Sequence[FtSamples]) -> None:
        self.script = list(script)
        self._i = 0
        self._running = False
        self.tared = 0

    def start(self) -> None:
        self._running = True

    def stop(self) -> None:
        self._running = False

    @property
    def running(self) -> bool:
        return self._running

    def samples(self) -> FtSamples:
        if not self._running:
            raise NotConnectedError("mock F/T sensor: samples() before start()")
        if self._i >= len(self.script):
            return FtSamples()
        out = self.script[self._i]
        self._i += 1
        return out

    def tare(self) -> None:
        self.tared += 1
