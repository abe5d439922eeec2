"""The device interfaces the runner uses; every back-end implements these.

The runner's loop, per FRI cycle::

    for m in robot.measurements():     # blocks until the next cycle (sim: steps physics)
        ft = sensor.samples()           # every sample since the last call
        ...
        robot.send(cmd)
"""

from __future__ import annotations

import abc
from collections.abc import Iterator
from types import TracebackType

from drivers.base.types import Command, FtSamples, Measurement


class RobotDriver(abc.ABC):
    """A robot clocked by its controller (FRI): one measurement per cycle, one command back."""

    @abc.abstractmethod
    def connect(self) -> None:
        """Open the link. Raises :class:`~drivers.errors.DriverError` subclasses."""

    @abc.abstractmethod
    def close(self) -> None:
        """Close the link; idempotent."""

    @property
    @abc.abstractmethod
    def connected(self) -> bool: ...

    @abc.abstractmethod
    def measurements(self) -> Iterator[Measurement]:
        """Yield one :class:`Measurement` per controller cycle until closed.

        Raises :class:`~drivers.errors.NotConnectedError` if not connected,
        :class:`~drivers.errors.DriverTimeoutError` if a cycle does not come,
        :class:`~drivers.errors.LinkLostError` if the link breaks.
        """

    @abc.abstractmethod
    def send(self, command: Command) -> None:
        """Answer the current cycle. A cycle without an answer repeats the last command."""

    def __enter__(self) -> RobotDriver:
        self.connect()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


class ForceTorqueSensor(abc.ABC):
    """A streaming F/T sensor (ATI Net F/T RDT or its model)."""

    @abc.abstractmethod
    def start(self) -> None:
        """Start streaming."""

    @abc.abstractmethod
    def stop(self) -> None:
        """Stop streaming; idempotent."""

    @property
    @abc.abstractmethod
    def running(self) -> bool: ...

    @abc.abstractmethod
    def samples(self) -> FtSamples:
        """Every sample since the last call, with timestamps [ns] and status words.

        Raises :class:`~drivers.errors.NotConnectedError` when not started.
        """

    def tare(self) -> None:  # noqa: B027 - optional capability, default no-op
        """Software bias (Net F/T command 0x0042): zero the current reading."""

    def __enter__(self) -> ForceTorqueSensor:
        self.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()
