"""The simulated FR3 in-process (``[robot] type = "franka-sim"``): the rig opens it on the
FR3's scene, ffexp's Franka driver holds it where it is, and a Franka rig without
pylibfranka fails with one line."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from drivers.factory import open_devices
from drivers.rig import load_rig

ROOT = Path(__file__).resolve().parents[1]


def test_the_rig_opens_the_fr3_and_the_driver_holds_it() -> None:
    rig = load_rig(ROOT / "rigs/franka-sim.toml")
    dev = open_devices(rig, source="rigs/franka-sim.toml",
                       scene_file=ROOT / "data/scenes/paper.toml")
    try:
        assert dev.metadata["driver"] == "franka-sim"
        assert dev.scene is not None and dev.scene.arm.model == "fr3"
        dev.robot.connect()
        states = dev.robot.measurements()
        first = next(states)
        for _ in range(100):  # 0.5 s holding, no command
            dev.robot.send(None)
            last = next(states)
    finally:
        dev.close()
    assert last.time_ns - first.time_ns == 100 * 5_000_000
    assert first.link.commanding and last.link.healthy
    assert np.linalg.norm(last.tcp_pose_m[:3, 3] - first.tcp_pose_m[:3, 3]) < 1e-5
    assert last.truth is not None


def test_a_franka_rig_without_pylibfranka_fails_with_one_line(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    import drivers.franka.backend as backend
    from ffexp.cli import app

    monkeypatch.setattr(backend, "find_spec", lambda name: None)
    res = CliRunner().invoke(app, ["run", str(ROOT / "protocols/method1_case1.toml"), "--rig",
                                   str(ROOT / "rigs/franka-emulator.toml"), "--out",
                                   str(tmp_path)])
    assert res.exit_code == 2, res.output
    lines = [line for line in res.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ")
    assert "robot.type: 'franka' needs pylibfranka" in lines[0]
    assert not list(tmp_path.glob("*.mcap"))


def test_the_rigs_sim_ft_sensor_reads_every_sample_of_the_fr3s_world() -> None:
    """``[ft] type = "sim"`` on the simulated FR3: the sensor is made after the robot, so the
    controller steps the world by ``SimWorld.advance`` (the lean step draws no F/T samples)
    and keeps the samples for the sensor: each cycle's block, contiguous in seq and time."""
    rig = load_rig(ROOT / "rigs/franka-sim.toml")
    dev = open_devices(rig, source="rigs/franka-sim.toml",
                       scene_file=ROOT / "data/scenes/paper.toml")
    try:
        dev.robot.connect()
        dev.sensor.start()
        states = dev.robot.measurements()
        next(states)
        blocks = []
        for _ in range(40):
            dev.robot.send(None)
            next(states)
            blocks.append(dev.sensor.samples())
        controller = dev.robot.controller  # type: ignore[attr-defined]
        assert controller.lean is None
    finally:
        dev.close()
    sizes = {len(b.seq) for b in blocks}
    assert len(sizes) == 1 and sizes.pop() > 0  # the same number every cycle, never none
    seq = np.concatenate([b.seq for b in blocks])
    t = np.concatenate([b.time_ns for b in blocks])
    assert np.all(np.diff(seq) == 1)
    assert np.all(np.diff(t) == t[1] - t[0]) and t[1] > t[0]


def test_the_fr3_without_an_ft_reader_is_stepped_lean() -> None:
    from drivers.description.scene import load_scene
    from drivers.franka.emulate.controller import Fr3SimController
    from drivers.world.ftstream import SimFtSensor
    from drivers.world.world import SimWorld

    scene = load_scene(ROOT / "data/scenes/paper-fr3.toml")
    alone = Fr3SimController(SimWorld(scene, seed=0))
    read = SimWorld(scene, seed=0)
    with_reader = Fr3SimController(read)
    SimFtSensor(read)  # made after the controller, as a rig opens them
    assert alone.lean is not None and with_reader.lean is None


def test_method1_aligns_on_the_simulated_fr3_with_its_sim_ft(tmp_path: Path) -> None:
    """docs/franka.md: the paper's Method I case I aligns on the in-process FR3 (its F/T
    the world's Mini45); a starved sensor made it abort on stale F/T data instead."""
    from ffexp.experiment import run_file
    from ffexp.rig_choice import RigChoice

    res = run_file(ROOT / "protocols/method1_case1.toml", ["run.timeout_s=8"],
                   rig=RigChoice(path=ROOT / "rigs/franka-sim.toml"), out_dir=tmp_path,
                   lean=True)
    assert res.outcome.aligned, res.outcome.reason
