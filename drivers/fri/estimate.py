"""The KRC's own external-wrench estimate (``estExtTcpFT``) read like an F/T sensor."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from drivers.base.guards import requires_open
from drivers.base.interfaces import FlagStream, ForceTorqueSensor
from drivers.base.types import FtSamples
from drivers.fri.types import FriMeasurement

__all__ = ["FriEstimateSensor", "MeasurementSource"]


class MeasurementSource(Protocol):
    """Anything that calls a listener with every accepted FRI measurement (a ``FriRobot``)."""

    def add_listener(self, callback: Callable[[FriMeasurement], None]) -> None: ...


class FriEstimateSensor(FlagStream, ForceTorqueSensor):
    """The KRC's ``estExtTcpFT`` (from joint torques) as a :class:`ForceTorqueSensor`.

    One sample per FRI cycle, stamped with the cycle's time; the wrench is
    already in our convention (environment on the tool, TCF at the TCP).
    ``tare`` subtracts the last sample from then on (like Net F/T 0x0042).

    Args:
        robot: the source of measurements (a :class:`~drivers.fri.driver.FriRobot`).
    """

    def __init__(self, robot: MeasurementSource) -> None:
        self.robot = robot
        self._lock = threading.Lock()
        self._time: list[int] = []
        self._seq: list[int] = []
        self._wrench: list[NDArray[np.float64]] = []
        self._bias = np.zeros(6)
        self._last: NDArray[np.float64] | None = None
        robot.add_listener(self._on_measurement)

    def _on_measurement(self, m: FriMeasurement) -> None:
        if not self._running:
            return
        with self._lock:
            self._time.append(m.time_ns)
            self._seq.append(m.seq)
            self._wrench.append(m.est_ext_tcp_ft)

    def start(self) -> None:
        with self._lock:
            self._time.clear()
            self._seq.clear()
            self._wrench.clear()
        super().start()

    @requires_open("FRI estimate F/T")
    def samples(self) -> FtSamples:
        with self._lock:
            t, s, w = self._time, self._seq, self._wrench
            self._time, self._seq, self._wrench = [], [], []
        if not t:
            return FtSamples()
        wrench = np.array(w, dtype=np.float64).reshape(-1, 6) - self._bias
        self._last = wrench[-1] + self._bias
        return FtSamples(
            time_ns=np.array(t, dtype=np.int64),
            seq=np.array(s, dtype=np.int64),
            wrench=wrench,
            status=np.zeros(len(t), dtype=np.uint32),
        )

    @requires_open("FRI estimate F/T")
    def tare(self) -> None:
        if self._last is not None:
            self._bias = self._last.copy()

