"""The mock back-end's entry: the ``mock`` robot (a scripted stationary robot) and the ``mock``
F/T sensor (a constant wrench plus seeded noise), for tests and dry runs. Light: the
drivers (:mod:`drivers.mock.driver`) are imported when a rig opens them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Annotated, Literal

from pydantic import Field

from drivers.base.backend import (
    Backend,
    DeviceConfig,
    FtBackend,
    OpenContext,
    OpenedRobot,
    OpenedSensor,
    RobotBackend,
)
from drivers.config import Vec3, Vec6

if TYPE_CHECKING:
    import numpy as np

__all__ = ["BACKEND", "MockFt", "MockRobotConfig"]


class MockRobotConfig(DeviceConfig):
    """A scripted stationary robot: the same state every cycle, commands recorded, no motion."""

    type: Literal["mock"] = "mock"
    cycles: Annotated[int, Field(ge=1)] = 2000
    """Cycles before the script ends."""
    cycle_s: Annotated[float, Field(ge=0.0005, le=0.1)] = 0.005
    tcp_position_m: Vec3 = (0.65, 0.0, 0.5)
    """TCP position in the base frame [m]."""
    tcp_rpy_rad: Vec3 = (0.0, 1.5707963267948966, 0.0)
    """TCP orientation, roll-pitch-yaw (fixed axes x, y, z) [rad]; default: tool Z along base X."""
    joint_pos_rad: tuple[float, ...] = (0.0, -0.3533, 0.0, 1.714, 0.0, 0.4965, 0.0)
    commanding: bool = True
    """The link reports command mode from the first cycle."""


class MockFt(DeviceConfig):
    """A constant wrench plus seeded Gaussian noise at a fixed rate."""

    type: Literal["mock"] = "mock"
    wrench_n_nm: Vec6 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    noise_std: tuple[float, float] = (0.03, 0.0005)
    """White noise per sample [N, N m]."""
    rate_hz: Annotated[float, Field(gt=0.0)] = 1000.0


def _rpy_pose(position: Sequence[float], rpy: Sequence[float]) -> np.ndarray:
    import numpy as np

    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), \
        math.sin(y)
    pose = np.eye(4)
    pose[:3, :3] = [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]
    pose[:3, 3] = position
    return pose


def _open_robot(cfg: MockRobotConfig, ctx: OpenContext) -> OpenedRobot:
    from drivers.mock.driver import stationary_robot

    robot = stationary_robot(
        cfg.cycles, cfg.cycle_s, _rpy_pose(cfg.tcp_position_m, cfg.tcp_rpy_rad),
        cfg.joint_pos_rad, cfg.commanding,
    )
    return OpenedRobot(robot, robot.now_ns, None,
                       {"driver": "mock", "mock_cycles": str(cfg.cycles)})


def _open_ft(cfg: MockFt, ctx: OpenContext, robot: OpenedRobot) -> OpenedSensor:
    from drivers.mock.driver import NoisyFtSensor

    return OpenedSensor(NoisyFtSensor(cfg.wrench_n_nm, cfg.noise_std, cfg.rate_hz,
                                      seed=ctx.seed, clock=robot.clock))


BACKEND = Backend(
    "mock",
    robots=(RobotBackend(MockRobotConfig, _open_robot, driver="mock", default_ft="mock"),),
    sensors=(FtBackend(MockFt, _open_ft),),
)
