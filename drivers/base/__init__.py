"""Robot-neutral device interfaces and the data types they exchange.

The names below are imported on first use (PEP 562): a back-end's entry
(:mod:`drivers.base.backend`), read by :mod:`drivers.registry` for the command
line's help, does not load numpy.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from drivers.base.interfaces import ForceTorqueSensor, RobotDriver
    from drivers.base.types import (
        NS_PER_S,
        AppliedCommand,
        ApplyStatus,
        CartesianCommand,
        Extras,
        FtSamples,
        FtStatus,
        GroundTruth,
        LinkHealth,
        RobotState,
    )

__all__ = [
    "NS_PER_S",
    "AppliedCommand",
    "ApplyStatus",
    "CartesianCommand",
    "Extras",
    "ForceTorqueSensor",
    "FtSamples",
    "FtStatus",
    "GroundTruth",
    "LinkHealth",
    "RobotDriver",
    "RobotState",
]


def __getattr__(name: str) -> Any:
    if name not in __all__:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    module = "interfaces" if name in ("ForceTorqueSensor", "RobotDriver") else "types"
    return getattr(import_module(f"{__name__}.{module}"), name)
