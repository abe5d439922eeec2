"""A simulated robot's scene is known before it opens and reaches the run as an object.

``RobotBackend.scene`` states it from the rig table (no world built); the opened robot
carries the same :class:`~drivers.description.scene.Scene` (``OpenedRobot.scene``,
``Devices.scene``) that its world runs; the recording's ``scene_json`` is that scene's
JSON; a real robot has none. Calibration reads its base scene without building a world.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from drivers import registry
from drivers.base.backend import OpenContext
from drivers.description.scene import Scene, load_scene
from drivers.factory import open_devices
from drivers.rig import validate_rig

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "data/scenes/paper.toml"
OVERRIDES = ("target.mass=20.0", "fri.cycle=0.002")


@pytest.mark.parametrize("robot", ["sim", "ur-sim"])
def test_the_opened_robot_runs_the_scene_its_backend_stated(robot: str) -> None:
    backend = registry.robot_backend(robot)
    assert backend.scene is not None
    rig = validate_rig({"robot": {"type": robot}, "ft": {"type": backend.default_ft}}, "<t>")
    stated = backend.scene(rig.robot, OpenContext("<t>", PAPER, OVERRIDES))
    assert isinstance(stated, Scene) and stated.target.mass == 20.0 and stated.fri.cycle == 0.002
    devices = open_devices(rig, source="<t>", scene_file=PAPER, scene_overrides=OVERRIDES)
    try:
        assert devices.scene == stated
        assert devices.robot.world.scene is devices.scene  # type: ignore[attr-defined]
        assert Scene.model_validate_json(devices.metadata["scene_json"]) == devices.scene
    finally:
        devices.close()
    if robot == "ur-sim":  # the UR5e takes the protocol's LWR4+ scene's place
        assert stated.arm.model == "ur5e" and load_scene(PAPER).arm.model == "lwr4"


def test_a_real_robot_has_no_scene() -> None:
    rig = validate_rig({"robot": {"type": "mock"}, "ft": {"type": "mock"}}, "<t>")
    assert registry.robot_backend("mock").scene is None
    devices = open_devices(rig, source="<t>", scene_file=PAPER)
    try:
        assert devices.scene is None
    finally:
        devices.close()


def test_calibrations_base_scene_is_read_without_a_world(monkeypatch: pytest.MonkeyPatch) -> None:
    from ffexp.calibrate.resim import base_scene

    # what the scene was before: the JSON of an opened sim rig's scene
    devices = open_devices(validate_rig({}, "<t>"), source="<t>", scene_file=PAPER,
                           scene_overrides=OVERRIDES)
    opened = json.loads(devices.metadata["scene_json"])
    devices.close()

    def no_world(*args: object, **kwargs: object) -> None:
        raise AssertionError("a world was built to read a scene")

    monkeypatch.setattr("drivers.world.world.SimWorld.__init__", no_world)
    assert base_scene(PAPER, OVERRIDES) == opened
