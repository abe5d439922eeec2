"""``ffexp check FILE...``: every kind of file, alone and together, checked as a run checks
it before its recording exists; nothing is written."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from typer.testing import CliRunner

from ffexp.cli import app

ROOT = Path(__file__).resolve().parents[1]
runner = CliRunner()


@pytest.mark.parametrize(("files", "kinds"), [
    (["protocols/method2.toml", "rigs/sim.toml"], ["run protocol on", "rig"]),
    (["protocols/paper.toml"], ["campaign, 5 run(s) on the built-in sim rig"]),
    (["data/scenes/paper.toml", "protocols/sec3_damping.toml"], ["scene", "sweep protocol"]),
    (["protocols/method1_case1.toml", "--rig", "rigs/mock.toml"], ["run protocol on"]),
    # the UR back-ends put the UR5e in an LWR4+ scene's place: said, not refused
    (["data/scenes/paper.toml", "rigs/ur5e-sim.toml"],
     ["ur5e-sim.toml (the rig's ur5e in place of the scene's lwr4)", "rig"]),
    (["protocols/method2.toml", "rigs/ur5e-lab.toml"],
     ["ur5e-lab.toml (the rig's ur5e in place of the scene's lwr4)", "rig"]),
    (["data/scenes/paper-ur5e.toml", "rigs/ur5e-sim.toml"], ["scene on", "rig"]),
])
def test_good_files_are_ok_one_line_each_and_nothing_is_written(
        files: list[str], kinds: list[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    args = [a if a.startswith("--") else str(ROOT / a) for a in files]
    result = runner.invoke(app, ["check", *args])
    assert result.exit_code == 0, result.stderr
    lines = result.stdout.splitlines()
    assert len(lines) == len(kinds)
    for line, kind in zip(lines, kinds, strict=True):
        assert line.startswith("ok: ") and kind in line, line
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize(("args", "needles"), [
    (["protocols/method2.toml", "--set", "scene.target.mu=-1"], ["target.mu"]),
    (["protocols/method2.toml", "--scene-set", "target.lateral=nan"], ["target.lateral"]),
    (["protocols/method2.toml", "rigs/ur5e-lab.toml", "--rig-set", "robot.robot_ip='1.2.3'"],
     ["robot.robot_ip"]),
    (["protocols/method2.toml", "--driver", "ur", "--rig-set", "robot.robot_ip='999.0.0.1'"],
     ["robot.robot_ip", "999.0.0.1"]),
    (["protocols/method2.toml", "--rig", "protocols/method2.toml"],
     ["is a run protocol, not a rig"]),
    # a UR5e scene on a KRC's LWR4+ (in-process, over FRI): the scene's arm and the robot
    (["data/scenes/paper-ur5e.toml", "rigs/sim.toml"],
     ["paper-ur5e.toml: arm.model: 'ur5e'", "rigs/sim.toml", "drives the lwr4"]),
    (["data/scenes/paper-ur5e.toml", "--driver", "fri", "--rig-set", "robot.robot_ip='127.0.0.1'"],
     ["arm.model", "'fri1'"]),
    (["protocols/method2.toml", "--set", 'scene.file="../data/scenes/paper-ur5e.toml"'],
     ["paper-ur5e.toml: arm.model: 'ur5e'", "built-in sim rig"]),
    (["protocols/paper.toml", "rigs/emulator.toml", "--set",
      'scene.file="../data/scenes/paper-ur5e.toml"'], ["arm.model", "rigs/emulator.toml"]),
])
def test_a_fault_of_a_file_or_of_the_combination_is_one_line_exit_2(
        args: list[str], needles: list[str], tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    full = [str(ROOT / a) if a.endswith(".toml") else a for a in args]
    result = runner.invoke(app, ["check", *full])
    assert result.exit_code == 2, result.stdout
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ")
    for needle in needles:
        assert needle in lines[0], lines[0]
    assert os.listdir(tmp_path) == []


SHIPPED = sorted([*ROOT.glob("protocols/*.toml"), *ROOT.glob("rigs/*.toml"),
                  *ROOT.glob("data/scenes/*.toml")])


#: The simulated rig each shipped scene's arm is checked on (a scene is checked on a
#: rig whose robot drives its arm).
RIG_OF_ARM = {"lwr4": "rigs/sim.toml", "ur5e": "rigs/ur5e-sim.toml",
              "fr3": "rigs/franka-sim.toml"}


def test_every_shipped_file_is_recognised_and_checks_ok() -> None:
    from drivers.description.scene import load_scene

    groups: dict[str, list[Path]] = {}
    for p in SHIPPED:
        arm = load_scene(p).arm.model if "scenes" in p.parts else "lwr4"
        groups.setdefault(RIG_OF_ARM[arm], []).append(p)
    assert len(groups) > 1  # scenes of other arms are shipped, each on its own rig
    kinds = set()
    for on, files in groups.items():
        result = runner.invoke(app, ["check", *map(str, files), "--rig", str(ROOT / on)])
        assert result.exit_code == 0, result.stderr
        assert len(result.stdout.splitlines()) == len(files)
        kinds |= {line.split(": ")[2].split(",")[0].split(" on ")[0]
                  for line in result.stdout.splitlines()}
    assert kinds == {"run protocol", "campaign", "study", "sweep protocol", "rig", "scene",
                     "impact protocol"}
