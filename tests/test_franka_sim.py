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
