"""The KRC's own external-wrench estimate (``estExtTcpFT``) read like an F/T sensor."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from drivers.base.guards import requires_open
from drivers.base.interfaces import FlagStream, ForceTorqueSensor
from drivers.base.types import FtSamples
from drivers.fri.types import FriMeasurement

__all__ = ["CAPACITY", "FriEstimateSensor", "MeasurementSource"]

#: Unread samples kept (at 1 kHz, 4 s without a read).
CAPACITY = 4096


@runtime_checkable
class MeasurementSource(Protocol):
    """Anything that calls a listener with every accepted FRI measurement (a ``FriRobot``)."""

    def add_listener(self, callback: Callable[[FriMeasurement], None]) -> None: ...


class FriEstimateSensor(FlagStream, ForceTorqueSensor):
    """The KRC's ``estExtTcpFT`` (from joint torques) as a :class:`ForceTorqueSensor`.

    One sample per FRI cycle, stamped with the cycle's time; the wrench is
    already in our convention (environment on the tool, TCF at the TCP). Every
    measurement from the robot's first on is a sample (also those before
    ``start``), until ``stop``.
    ``tare`` subtracts the last sample from then on (like Net F/T 0x0042).

    Args:
        robot: the source of measurements (a :class:`~drivers.fri.driver.FriRobot`).
    """

    def __init__(self, robot: MeasurementSource) -> None:
        self.robot = robot
        self._lock = threading.Lock()
        # the samples since the last read, copied into preallocated rows (the
        # listener runs on the link's I/O thread: nothing allocated there)
        self._time = np.zeros(CAPACITY, dtype=np.int64)
        self._seq = np.zeros(CAPACITY, dtype=np.int64)
        self._wrench = np.zeros((CAPACITY, 6))
        self._n = 0
        self._stopped = False  # samples are kept from the robot's first measurement on
        self.dropped = 0
        """Samples overwritten before a read (more than :data:`CAPACITY` unread)."""
        self._bias = np.zeros(6)
        self._last: NDArray[np.float64] | None = None
        robot.add_listener(self._on_measurement)

    def _on_measurement(self, m: FriMeasurement) -> None:
        if self._stopped:
            return
        with self._lock:
            n = self._n
            if n == CAPACITY:  # nobody reads: keep the newest
                self._time[:-1] = self._time[1:]
                self._seq[:-1] = self._seq[1:]
                self._wrench[:-1] = self._wrench[1:]
                n = CAPACITY - 1
                self.dropped += 1
            self._time[n] = m.time_ns
            self._seq[n] = m.seq
            self._wrench[n] = m.est_ext_tcp_ft
            self._n = n + 1

    def start(self) -> None:
        # keeps what came since the robot connected: whether the link's first
        # measurement arrives before or after this call does not change the samples
        self._stopped = False
        super().start()

    def stop(self) -> None:
        self._stopped = True
        with self._lock:
            self._n = 0
        super().stop()

    @requires_open("FRI estimate F/T")
    def samples(self) -> FtSamples:
        with self._lock:
            n = self._n
            if n == 0:
                return FtSamples()
            t, q, w = self._time[:n].copy(), self._seq[:n].copy(), self._wrench[:n].copy()
            self._n = 0
        w -= self._bias
        self._last = w[-1] + self._bias
        return FtSamples(time_ns=t, seq=q, wrench=w, status=np.zeros(n, dtype=np.uint32))

    @requires_open("FRI estimate F/T")
    def tare(self) -> None:
        if self._last is not None:
            self._bias = self._last.copy()

