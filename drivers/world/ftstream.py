"""The simulated F/T sensor: the Mini45 model of a :class:`SimWorld`, read like a Net F/T stream.

It only reads the world. The simulated robot is the lockstep KRC of
:mod:`drivers.fri.emulate.lockstep` (it speaks FRI, which this package does not).
"""

from __future__ import annotations

from drivers.base.guards import requires_open
from drivers.base.interfaces import FlagStream, ForceTorqueSensor
from drivers.base.types import FtSamples
from drivers.errors import NotConnectedError
from drivers.world.world import SimWorld

__all__ = ["SimFtSensor"]


class SimFtSensor(FlagStream, ForceTorqueSensor):
    """Every F/T sample the world produced since the last call (the world is stepped elsewhere)."""

    def __init__(self, world: SimWorld) -> None:
        self.world = world
        world.ft_read = True  # its samples are drawn every cycle from now on

    def start(self) -> None:
        self.world.ft_samples()  # a fresh stream starts now
        super().start()

    def samples(self) -> FtSamples:
        if not self._running:  # requires_open, inline (every cycle)
            raise NotConnectedError("sim F/T sensor: samples() before connect/start")
        return self.world.ft_samples()

    @requires_open("sim F/T sensor")
    def tare(self) -> None:
        self.world.tare_ft()
