"""MuJoCo world: LWR4+ with its KRC impedance law, air-bed target, funnels, F/T sensor.

A physics world only (:class:`SimWorld`: arm commands in, arm states out,
see :mod:`drivers.sim.arm`) and the sensor that reads it
(:class:`SimFtSensor`). The FRI link in front of it is :mod:`drivers.emulate`; the rig
it builds is a scene (:mod:`drivers.description`).

The names below are imported on first use (PEP 562), so that the back-end's
entry (:mod:`drivers.sim.backend`, read by :mod:`drivers.registry` for the
command line's help) does not load MuJoCo.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
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

_WHERE = {
    "ArmCommand": "arm", "ArmMode": "arm", "ArmState": "arm", "ArmWarning": "arm",
    "SimFtSensor": "driver", "SimWorld": "world",
}


def __getattr__(name: str) -> Any:
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(import_module(f"{__name__}.{module}"), name)
