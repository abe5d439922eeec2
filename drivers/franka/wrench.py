"""The Franka's external wrench estimate read like an F/T sensor (``[ft] type = "franka-wrench"``).

``O_F_ext_hat_K`` (the robot's estimate from its joint torque sensors, base frame at the
EE) turned into the TCF, as :class:`~drivers.franka.driver.FrankaRobot` reports it in
``ext_wrench_n_nm``: one sample per state the robot yields, stamped with its time; ``tare``
subtracts the last sample from then on.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from drivers.base.guards import requires_open
from drivers.base.interfaces import FlagStream, ForceTorqueSensor
from drivers.base.types import FtSamples, RobotState
from drivers.franka.driver import FrankaRobot

__all__ = ["FrankaWrenchSensor"]


class FrankaWrenchSensor(FlagStream, ForceTorqueSensor):
    """The wrench a :class:`FrankaRobot` reports, as a :class:`ForceTorqueSensor`."""

    def __init__(self, robot: FrankaRobot) -> None:
        self._pending: list[tuple[int, int, NDArray[np.float64]]] = []
        self._bias = np.zeros(6)
        self._last: NDArray[np.float64] | None = None
        robot.add_listener(self._on_state)

    def _on_state(self, state: RobotState) -> None:
        if self.running and state.ext_wrench_n_nm is not None:
            self._pending.append((state.time_ns, state.link.cycle,
                                  np.asarray(state.ext_wrench_n_nm, dtype=np.float64)))

    def stop(self) -> None:
        self._pending = []
        super().stop()

    @requires_open("Franka wrench F/T")
    def samples(self) -> FtSamples:
        got, self._pending = self._pending, []
        if not got:
            return FtSamples()
        wrench = np.array([w for _t, _s, w in got])
        self._last = wrench[-1].copy()
        return FtSamples(time_ns=np.array([t for t, _s, _w in got], dtype=np.int64),
                         seq=np.array([s for _t, s, _w in got], dtype=np.int64),
                         wrench=wrench - self._bias,
                         status=np.zeros(len(got), dtype=np.uint32))

    def tare(self) -> None:
        if self._last is not None:
            self._bias = self._last.copy()
