"""The simulated FR3 in-process: ffexp's Franka driver on the FR3's controller, lockstep.

The ``franka-sim`` robot of a rig: a :class:`~drivers.franka.driver.FrankaRobot` (the very
driver of a real Franka, its 1 kHz impedance law included) whose link is
:class:`LoopbackFci`, the robot's side in-process: each :meth:`~LoopbackFci.write_once`
steps the controller (:class:`~drivers.franka.emulate.controller.Fr3SimController`) one
millisecond with the torques, and each state crosses the wire's codec (float32), so a run
here equals the same run over libfranka's protocol against ``ffexp emulate --robot fr3
--pacing lockstep``, with the ground truth added in-process (:class:`SimFrankaRobot`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from drivers.base.backend import OpenContext, OpenedRobot
from drivers.base.types import F64, RobotState
from drivers.description.scene import Scene
from drivers.franka import codec
from drivers.franka.config import FrankaSimConfig
from drivers.franka.driver import FrankaRobot
from drivers.franka.emulate.controller import Fr3SimController
from drivers.franka.link import FciState, state_from_record
from drivers.world.world import SimWorld

__all__ = ["LoopbackFci", "SimFrankaRobot", "open_sim"]


class LoopbackFci:
    """The robot's side of the torque loop in-process (module docstring)."""

    def __init__(self, controller: Fr3SimController) -> None:
        self.controller = controller
        self._command = np.zeros((), dtype=codec.ROBOT_COMMAND)

    @property
    def address(self) -> str:
        return "in-process"

    def connect(self) -> FciState:
        self.controller.start_motion()
        return self.read_once()

    def read_once(self) -> FciState:
        wire = self.controller.state().tobytes()
        return state_from_record(codec.decode(codec.ROBOT_STATE, wire))

    def write_once(self, tau: F64) -> None:
        c = self._command
        c["message_id"] = self.controller.message_id
        c["tau_J_d"] = tau
        self.controller.step(codec.decode(codec.ROBOT_COMMAND, c.tobytes()))

    def close(self) -> None:
        self.controller.finish_motion()


class SimFrankaRobot(FrankaRobot):
    """ffexp's Franka driver on the simulated FR3 in-process (module docstring)."""

    def __init__(self, world: SimWorld, settings: FrankaSimConfig,
                 where: str = "FrankaSimConfig") -> None:
        self.world = world
        self.controller = Fr3SimController(world)
        self.loopback = LoopbackFci(self.controller)
        super().__init__(settings, where, link=lambda: self.loopback)
        self._truth = settings.truth

    @property
    def address(self) -> str:
        return "in-process FR3"

    def _robot_state(self, state: FciState) -> RobotState:
        out = super()._robot_state(state)
        if self._truth:
            out.truth = self.world.last_state.truth
        return out


def open_sim(cfg: FrankaSimConfig, ctx: OpenContext, path: Path, scene: Scene) -> OpenedRobot:
    """The ``franka-sim`` robot of a rig on a world of ``scene`` (read from ``path``)."""
    world = SimWorld(scene, seed=ctx.seed)
    robot = SimFrankaRobot(world, cfg, where=ctx.where("robot"))
    meta = {"driver": "franka-sim", "scene_file": str(path),
            "scene_json": scene.model_dump_json()}
    return OpenedRobot(robot, robot.now_ns, None, meta, [(path.name, path.read_bytes())],
                       scene=scene)
