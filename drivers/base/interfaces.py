"""The device interfaces the experiment loop uses; every back-end implements these.

The loop, per robot cycle (``ffexp/loop.py``)::

    for state in robot.measurements():  # blocks until the next cycle (sim: steps physics)
        ft = sensor.samples()            # every sample since the last call
        ...
        applied = robot.send(cmd)        # what the robot really applies, beside cmd
"""

from __future__ import annotations

import abc
from collections.abc import Iterator
from types import TracebackType

from drivers.base.types import (
    AppliedCommand,
    CartesianCommand,
    FtSamples,
    RobotState,
    TargetObservation,
)


class RobotDriver(abc.ABC):
    """A robot clocked by its controller: one state per cycle, one command back."""

    @abc.abstractmethod
    def connect(self) -> None:
        """Open the link. Raises :class:`~drivers.errors.DriverError` subclasses."""

    @abc.abstractmethod
    def close(self) -> None:
        """Close the link; idempotent."""

    @property
    @abc.abstractmethod
    def connected(self) -> bool: ...

    @property
    def is_open(self) -> bool:
        """What :func:`~drivers.base.guards.requires_open` checks (default: connected)."""
        return self.connected

    @abc.abstractmethod
    def measurements(self) -> Iterator[RobotState]:
        """Yield one :class:`RobotState` per controller cycle until closed.

        Raises :class:`~drivers.errors.NotConnectedError` if not connected,
        :class:`~drivers.errors.DriverTimeoutError` if a cycle does not come,
        :class:`~drivers.errors.LinkLostError` if the link breaks.
        """

    @abc.abstractmethod
    def send(self, command: CartesianCommand | None) -> AppliedCommand:
        """Answer the current cycle; return what the robot really gets.

        ``None`` keeps the robot's own set-point (FRI: mirror the commanded
        position). While the link is not commanding, a driver sends what its
        protocol requires (FRI mirrors) and says so in the returned status.
        The driver copies what it keeps: the caller may reuse ``command``.
        A cycle without an answer repeats the last command.
        """

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

    @property
    def is_open(self) -> bool:
        """What :func:`~drivers.base.guards.requires_open` checks (default: running)."""
        return self.running

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



class FlagStream:
    """``start``/``stop``/``running`` for a sensor whose stream is a flag.

    For models and stand-ins that produce samples on demand (no socket, no
    thread): mix it in before :class:`ForceTorqueSensor`; a subclass with
    work to do on start overrides ``start`` and calls ``super().start()``.
    """

    _running: bool = False

    def start(self) -> None:
        self._running = True

    def stop(self) -> None:
        self._running = False

    @property
    def running(self) -> bool:
        return self._running


class TargetTracker(abc.ABC):
    """A device that tracks the floating target (beside the robot and the F/T sensor).

    Its capture runs on its own (a thread, a process, or the simulator's
    cycle) and never blocks the control loop: :meth:`latest` returns at once
    with the newest pose it has, or ``None`` before the first.
    """

    @abc.abstractmethod
    def start(self) -> None:
        """Begin capturing (open the source)."""

    @abc.abstractmethod
    def stop(self) -> None:
        """Stop capturing and release the source; idempotent."""

    @abc.abstractmethod
    def latest(self) -> TargetObservation | None:
        """The newest observation (never blocks)."""
