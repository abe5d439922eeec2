"""The UR's own wrench read like an F/T sensor: an ``[ft]`` source beside the Net F/T.

``source = "tcp_force"``: ``actual_TCP_force`` (the controller's wrench at the
TCP, payload compensated), rotated from the base frame into the TCF as
:class:`~drivers.ur.driver.UrRobot` reports it in ``ext_wrench_n_nm``.
``source = "ft_raw"``: ``ft_raw_wrench``, the flange sensor's raw reading,
as the controller reports it (its frame and sign are UR's: docs/ur.md).
One sample per state the robot yields, stamped with its time; ``tare``
subtracts the last sample from then on (like Net F/T's software bias).
"""

from __future__ import annotations

from typing import Final, Literal

import numpy as np
from numpy.typing import NDArray

from drivers.base.guards import requires_open
from drivers.base.interfaces import FlagStream, ForceTorqueSensor
from drivers.base.types import FtSamples, RobotState
from drivers.ur.driver import UrExtras, UrRobot

#: Unread samples kept (at 500 Hz, about 8 s without a read); older ones are dropped.
CAPACITY: Final = 4096

WrenchSource = Literal["tcp_force", "ft_raw"]


class UrWrenchSensor(FlagStream, ForceTorqueSensor):
    """The wrench a :class:`~drivers.ur.driver.UrRobot` reports, as a :class:`ForceTorqueSensor`."""

    def __init__(self, robot: UrRobot, source: WrenchSource = "tcp_force") -> None:
        self.source: WrenchSource = source
        self._time = np.zeros(CAPACITY, dtype=np.int64)
        self._seq = np.zeros(CAPACITY, dtype=np.int64)
        self._wrench = np.zeros((CAPACITY, 6))
        self._n = 0
        self.dropped = 0
        """Samples dropped unread (more than :data:`CAPACITY` between two reads)."""
        self._bias = np.zeros(6)
        self._last: NDArray[np.float64] | None = None
        robot.add_listener(self._on_state)

    def _on_state(self, state: RobotState) -> None:
        if not self.running:
            return
        if self.source == "ft_raw":
            extras = state.extras
            if not isinstance(extras, UrExtras):
                return
            wrench = extras.ft_raw_wrench
        elif state.ext_wrench_n_nm is None:
            return
        else:
            wrench = state.ext_wrench_n_nm
        n = self._n
        if n == CAPACITY:
            self._time[:-1], self._seq[:-1] = self._time[1:], self._seq[1:]
            self._wrench[:-1] = self._wrench[1:]
            n = CAPACITY - 1
            self.dropped += 1
        self._time[n] = state.time_ns
        self._seq[n] = state.link.cycle
        self._wrench[n] = wrench
        self._n = n + 1

    def stop(self) -> None:
        self._n = 0
        super().stop()

    @requires_open("UR wrench F/T")
    def samples(self) -> FtSamples:
        n, self._n = self._n, 0
        if n == 0:
            return FtSamples()
        w = self._wrench[:n] - self._bias
        self._last = self._wrench[n - 1].copy()
        return FtSamples(time_ns=self._time[:n].copy(), seq=self._seq[:n].copy(), wrench=w,
                         status=np.zeros(n, dtype=np.uint32))

    @requires_open("UR wrench F/T")
    def tare(self) -> None:
        if self._last is not None:
            self._bias = self._last
