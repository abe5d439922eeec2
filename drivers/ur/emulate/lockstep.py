"""The simulated UR5e in-process: ffexp's URScript program on the sim world in lockstep, no sockets.

The ``ur-sim`` robot of a rig: a :class:`~drivers.ur.driver.UrRobot` (the very
driver of a real UR, with the rig's force-mode settings) whose RTDE link is
:class:`LoopbackRtde`, an in-process stand-in for the controller's side:
each :meth:`~LoopbackRtde.receive_latest` runs the controller
(:class:`~drivers.ur.emulate.controller.UrSimController`) one output period
with the input registers last sent, and returns its outputs as the data
package the client would have decoded. The values are those the RTDE emulator
sends in lockstep (doubles and integers cross the wire exactly), so a run here
equals the same run over RTDE against ``ffexp emulate --robot ur5e --pacing
lockstep``, with the ground truth added in-process (:class:`SimUrRobot`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from drivers.base.backend import OpenContext, OpenedRobot
from drivers.base.types import RobotState
from drivers.description.scene import Scene
from drivers.errors import LinkLostError
from drivers.ur.config import UrSimConfig
from drivers.ur.driver import UrRobot
from drivers.ur.emulate.controller import UrSimController
from drivers.ur.registers import INPUT_NAMES
from drivers.ur.rtde.codec import ControllerVersion, DataPackage
from drivers.ur.rtde.fields import Recipe
from drivers.ur.rtde.variables import INPUTS, OUTPUTS
from drivers.world.world import SimWorld

__all__ = ["CONTROLLER_VERSION", "LoopbackRtde", "SimUrRobot", "open_sim"]

#: The controller version the emulated UR reports (a PolyScope 5.15 e-Series).
CONTROLLER_VERSION = ControllerVersion(5, 15, 0, 0)


class LoopbackRtde:
    """The controller's side of RTDE in-process (module docstring): the link of a
    :class:`UrRobot` to a :class:`UrSimController`."""

    def __init__(self, controller: UrSimController) -> None:
        self.controller = controller
        self.skipped = 0
        self._open = False
        self._outputs: Recipe | None = None
        self._every = 1
        self._inputs: dict[int, Recipe] = {}

    @property
    def is_open(self) -> bool:
        return self._open

    def connect(self) -> None:
        self._open = True

    def close(self) -> None:
        self._open = False

    def controller_version(self) -> ControllerVersion:
        return CONTROLLER_VERSION

    def setup_outputs(self, names: Sequence[str], frequency_hz: float) -> Recipe:
        self._outputs = Recipe(1, tuple(names), tuple(OUTPUTS[n] for n in names))
        base_hz = 1.0 / self.controller.world.cycle_s
        self._every = max(1, round(base_hz / frequency_hz))
        return self._outputs

    def setup_inputs(self, names: Sequence[str]) -> Recipe:
        recipe = Recipe(2 + len(self._inputs), tuple(names), tuple(INPUTS[n] for n in names))
        self._inputs[recipe.recipe_id] = recipe
        return recipe

    def start(self) -> None:
        if self._outputs is None:
            raise LinkLostError("in-process UR: start before an output recipe")

    def receive_latest(self, timeout_s: float | None = None) -> DataPackage:
        if not self._open or self._outputs is None:
            raise LinkLostError("in-process UR: the link is closed")
        for _ in range(self._every):
            values = self.controller.step()
        outputs = self._outputs
        record = outputs.empty()
        record[()] = tuple([values[name] for name in outputs.names])  # (every field at once)
        return DataPackage(outputs.recipe_id, record)

    def send(self, recipe: Recipe, values: Mapping[str, object] | np.ndarray) -> None:
        if isinstance(values, np.ndarray):  # (a record's values as Python numbers)
            if recipe.names == INPUT_NAMES:  # the driver's record: every register, in order
                self.controller.take_program_inputs(values.item())
            else:
                self.controller.take(dict(zip(recipe.names, values.item(), strict=True)))
        else:
            self.controller.take(values)


class SimUrRobot(UrRobot):
    """The UR driver on the simulated UR in-process (module docstring)."""

    def __init__(self, world: SimWorld, settings: UrSimConfig, where: str = "UrSimConfig") -> None:
        self.world = world
        self.controller = UrSimController(world)
        self.loopback = LoopbackRtde(self.controller)
        super().__init__(settings.model_copy(update={"script": "installed"}), where,
                         link=lambda host, port, timeout_s: self.loopback)
        self._truth = settings.truth

    def _state(self, rec: np.ndarray) -> RobotState:
        state = super()._state(rec)
        if self._truth:
            state.truth = self.world.last_state.truth
        return state


def open_sim(cfg: UrSimConfig, ctx: OpenContext, path: Path, scene: Scene) -> OpenedRobot:
    """The ``ur-sim`` robot of a rig: :class:`SimUrRobot` on a world of ``scene`` (read from
    ``path``), with its run metadata and the scene file attached."""
    world = SimWorld(scene, seed=ctx.seed)
    robot = SimUrRobot(world, cfg, where=ctx.where("robot"))
    meta = {"driver": "ur-sim", "scene_file": str(path), "scene_json": scene.model_dump_json()}
    return OpenedRobot(robot, lambda: world.cycle * world.cycle_ns, None, meta,
                       [(path.name, path.read_bytes())], scene=scene)
