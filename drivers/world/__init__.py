"""The simulated world, neutral ground for every simulated robot: a MuJoCo model of the
scene's arm with its controller's joint interface, the free-floating target on its bed
(or in zero g), the funnels and the Mini45 F/T model (:class:`SimWorld`: arm commands in,
arm states out, see :mod:`drivers.world.arm`), and :class:`SimFtSensor`, the stream that
reads the world's F/T samples.

No back-end lives here: each robot family's emulated controller and in-process robot
(``drivers/<family>/emulate/``) and the ``sim`` F/T sensor and tracker
(:mod:`drivers.sim.backend`) import this package, and it imports none of them. The
rig it builds is a scene (:mod:`drivers.description`).

The names below are imported on first use (PEP 562), so that importing the package does
not load MuJoCo.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from drivers.world.arm import ArmCommand, ArmMode, ArmState, ArmWarning
    from drivers.world.ftstream import SimFtSensor
    from drivers.world.world import SimWorld

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
    "SimFtSensor": "ftstream", "SimWorld": "world",
}


def __getattr__(name: str) -> Any:
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(import_module(f"{__name__}.{module}"), name)
