"""Robot-neutral device interfaces and the data types they exchange."""

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
