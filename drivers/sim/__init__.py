"""MuJoCo world: LWR4+ with its KRC impedance law, air-bed target, funnels, F/T sensor.

A physics world only (:class:`SimWorld`: arm commands in, arm states out,
see :mod:`drivers.sim.arm`) and the sensor that reads it
(:class:`SimFtSensor`). The FRI link in front of it is :mod:`drivers.emulate`; the rig
it builds is a scene (:mod:`drivers.description`).
"""

from drivers.sim.arm import ArmCommand, ArmMode, ArmState, ArmWarning
from drivers.sim.driver import SimFtSensor
from drivers.sim.world import SimWorld

__all__ = [
    "ArmCommand",
    "ArmMode",
    "ArmState",
    "ArmWarning",
    "SimFtSensor",
    "SimWorld",
]
