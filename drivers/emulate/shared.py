"""One simulated world served by several emulators: each arm of a two-arm world
(:mod:`drivers.carrier.plant`) behind its own family's server, stepped in lockstep.

:class:`SharedWorld` is the rendezvous. Each server calls :meth:`SharedWorld.arrive` for
its ``k``-th step (its clients have answered step ``k - 1``; their targets came through
:meth:`SharedWorld.set_target`); the world runs cycle ``k`` once every server still
present has arrived, and each gets its arm's view of the state. Step 0 is the start
state, not stepped. A server that leaves (its emulator killed or closed,
:meth:`SharedWorld.leave`) no longer holds the others: its arm keeps its last target,
as a controller that stopped holds its brakes. Knows no robot family: a role is a name
(``chaser``, ``carrier``).
"""

from __future__ import annotations

import threading

import numpy as np

from drivers.base.types import F64
from drivers.carrier.plant import CarrierPlant, JointReading, PlantCycle
from drivers.errors import DriverTimeoutError

__all__ = ["ROLES", "SharedWorld"]

#: The arms of a two-arm world, by role.
ROLES = ("chaser", "carrier")


class SharedWorld:
    """A :class:`~drivers.carrier.plant.CarrierPlant` stepped by one server per role."""

    def __init__(self, plant: CarrierPlant, chaser_q0: F64, carrier_q0: F64, *,
                 timeout_s: float = 10.0) -> None:
        self.plant = plant
        self.timeout_s = timeout_s
        zero = {"chaser": np.zeros_like(chaser_q0), "carrier": np.zeros_like(carrier_q0)}
        self._targets: dict[str, tuple[F64, F64]] = {
            "chaser": (np.array(chaser_q0, dtype=np.float64), zero["chaser"]),
            "carrier": (np.array(carrier_q0, dtype=np.float64), zero["carrier"])}
        self._chaser_q = self._targets["chaser"][0]
        self._present = set(ROLES)
        self._arrived: dict[str, int] = {}
        self._cond = threading.Condition()
        self._k = 0
        self._state = plant.start()
        self._fine: list[tuple[float, ...]] = []
        self.steps = 0
        """Cycles the world has run."""

    def set_target(self, role: str, q: F64, qd: F64) -> None:
        """The role's joint targets for the next cycle (its server's thread)."""
        with self._cond:
            self._targets[role] = (np.array(q, dtype=np.float64), np.array(qd, dtype=np.float64))

    def arrive(self, role: str, k: int) -> JointReading:
        """The role's server is at its step ``k``: the world's cycle ``k`` once every
        present server is (raises :class:`~drivers.errors.DriverTimeoutError` after
        ``timeout_s`` without the others)."""
        with self._cond:
            self._arrived[role] = k
            self._advance()
            if not self._cond.wait_for(lambda: self._k >= k, timeout=self.timeout_s):
                missing = sorted(r for r in self._present if self._arrived.get(r, -1) < k)
                raise DriverTimeoutError(f"shared world: step {k} waited {self.timeout_s:g} s "
                                         f"for {', '.join(missing)}")
            return self._view(role)

    def leave(self, role: str) -> None:
        """The role's server is gone: the others step without it."""
        with self._cond:
            self._present.discard(role)
            self._advance()

    def drain_truth(self) -> list[tuple[float, ...]]:
        """The contact's truth rows since the last call."""
        with self._cond:
            out, self._fine = self._fine, []
            return out

    def _advance(self) -> None:
        while self._present and all(self._arrived.get(r, -1) > self._k for r in self._present):
            (cq, cqd), (hq, hqd) = self._targets["carrier"], self._targets["chaser"]
            self._state = self.plant.step(cq, cqd, hq, hqd)
            self._chaser_q = hq
            self._fine.extend(self._state.fine)
            self._k += 1
            self.steps += 1
            self._cond.notify_all()

    def _view(self, role: str) -> JointReading:
        s: PlantCycle = self._state
        if role == "carrier":
            return JointReading(s.t_s, s.carrier_q, s.carrier_qd, s.samples)
        return JointReading(s.t_s, self._chaser_q, self._targets["chaser"][1])
