"""Device interfaces and the data types they exchange."""

from drivers.base.interfaces import ForceTorqueSensor, RobotDriver
from drivers.base.types import (
    CmdFlags,
    Command,
    ControlMode,
    FriQuality,
    FriState,
    FtSamples,
    FtStatus,
    GroundTruth,
    Measurement,
)

__all__ = [
    "CmdFlags",
    "Command",
    "ControlMode",
    "ForceTorqueSensor",
    "FriQuality",
    "FriState",
    "FtSamples",
    "FtStatus",
    "GroundTruth",
    "Measurement",
    "RobotDriver",
]
