"""``ffexp resimulate`` and ``ffexp calibrate`` on recordings of the UR e-Series and Franka
families: Method I recorded on the simulated UR5e (``ur-sim``) and FR3 (``franka-sim``),
replayed open loop through their own back-end's ``Replay`` (the applied commands of
``/control/command``, held cycles as ``send(None)``)."""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from ffexp.cli import app
from ffexp.experiment import run_file
from ffexp.recording import load
from ffexp.rig_choice import RigChoice

ROOT = Path(__file__).resolve().parents[1]
PROTOCOL = ROOT / "protocols/method1_case1.toml"
RIGS = {"ur-sim": ROOT / "rigs/ur5e-sim.toml", "franka-sim": ROOT / "rigs/franka-sim.toml"}
#: The bed friction the calibration recordings are made at (the scene's default: 0.0085).
MU_TRUE = 0.006
MU_DEFAULT = 0.0085
runner = CliRunner()
pytestmark = pytest.mark.slow


def _record(out: Path, robot: str, sets: list[str], rig: tuple[str, ...] = (),
            timeout_s: float = 2.0) -> Path:
    scene = ["scene.set=[" + ", ".join(f'"{s}"' for s in sets) + "]"] if sets else []
    return run_file(PROTOCOL, [f"run.timeout_s={timeout_s}", *scene],
                    rig=RigChoice(path=RIGS[robot], overrides=rig), out_dir=out).path


@pytest.fixture(scope="module", params=["ur-sim", "franka-sim"])
def family(request: pytest.FixtureRequest,
           tmp_path_factory: pytest.TempPathFactory) -> tuple[str, Path, Path]:
    """Per robot: Method I as recorded (2 s, full recording), and the target set gliding
    by an impulse far from the arm at bed friction :data:`MU_TRUE`, seen by a tracker."""
    robot: str = request.param
    out = tmp_path_factory.mktemp(robot)
    plain = _record(out / "plain", robot, [])
    glide = _record(out / "glide", robot,
                    [f"target.mu={MU_TRUE}", "target.distance=0.2",
                     "target.velocity=[0.0, 0.1, 0.0]"], rig=("tracker.type=sim",),
                    timeout_s=1.6)
    return robot, plain, glide


def _ft_noise_n(rec: Path) -> float:
    """The recorded sensor's white noise with its quantisation, per force axis [N]."""
    ft = json.loads(load(rec, ()).metadata["run"]["scene_json"])["ft_sensor"]
    return float(np.hypot(ft["noise_std"][0], ft["resolution"][0] / np.sqrt(12.0)))


def test_replay_of_a_family_recording_gives_its_arm_exactly_and_its_ft_to_the_noise(
        family: tuple[str, Path, Path], tmp_path: Path) -> None:
    robot, rec, _ = family
    sim = tmp_path / "sim.mcap"
    result = runner.invoke(app, ["resimulate", str(rec), "--out", str(sim)])
    assert result.exit_code == 0, result.stderr
    a, b = load(rec), load(sim)
    assert b.metadata["resimulation"]["driver"] == robot
    sa, sb = a.topic("/robot/state"), b.topic("/robot/state")
    assert len(sa) == len(sb) > 300  # the whole run, cycle by cycle (2 s: 400 or 1000)
    tcp = sa["tcp_pose"].reshape(-1, 4, 4)[:, :3, 3]
    assert np.ptp(tcp, axis=0).max() > 0.005  # the arm moved: exactness says something
    # the same simulator, the same commands (held cycles held): the same arm, bit for bit
    assert np.array_equal(sa["tcp_pose"], sb["tcp_pose"])
    assert np.array_equal(sa["joint_pos"], sb["joint_pos"], equal_nan=True)
    # the F/T: the recorded sensor's noise, quantisation and drift, not in the replay
    ra, rb = a.topic("/ft/raw"), b.topic("/ft/raw")
    # paired by log time (a world sensor's replay has none before its delay's first sample)
    _, ia, ib = np.intersect1d(ra.log_time_ns, rb.log_time_ns, return_indices=True)
    assert len(ia) >= len(ra) - 2
    # the replay carries the recording's bias: the difference's mean is about 0
    d = ra["wrench"][ia, :3] - rb["wrench"][ib, :3]
    assert np.abs(d.mean(axis=0)).max() < 0.02
    rms = float(np.sqrt(np.mean(d ** 2)))
    noise = _ft_noise_n(rec)
    assert 0.8 * noise < rms < 1.5 * noise, (rms, noise)


#: Driver settings away from the rigs' (the replay takes them from the recorded rig).
SETTINGS = {"ur-sim": ("robot.servo_gain=600.0", "robot.force_mode_damping=0.05",
                       "ft.source=ft_raw"),
            "franka-sim": ("robot.nullspace_stiffness_nmprad=30.0",
                           "robot.stiffness_max_npm_nmprad=[2500.0, 250.0]")}


@pytest.mark.parametrize("robot", ["ur-sim", "franka-sim"])
def test_a_rig_with_its_own_driver_settings_replays_with_them(robot: str,
                                                               tmp_path: Path) -> None:
    # measured: replayed with the table's defaults instead, the UR's TCP parts by 7.6 cm,
    # the FR3's by 0.15 mm; with the recorded rig's settings, not at all
    rec = _record(tmp_path / "rec", robot, [], rig=SETTINGS[robot])
    sim = tmp_path / "sim.mcap"
    result = runner.invoke(app, ["resimulate", str(rec), "--out", str(sim)])
    assert result.exit_code == 0, result.stderr
    a, b = load(rec), load(sim)
    assert np.array_equal(a.topic("/robot/state")["tcp_pose"], b.topic("/robot/state")["tcp_pose"])
    # the F/T read from the recorded source (the UR's ft_raw: without contact it equals
    # tcp_force here up to the bias, so this checks the table is taken, not which source)
    ra, rb = a.topic("/ft/raw"), b.topic("/ft/raw")
    _, ia, ib = np.intersect1d(ra.log_time_ns, rb.log_time_ns, return_indices=True)
    d = ra["wrench"][ia, :3] - rb["wrench"][ib, :3]
    assert float(np.sqrt(np.mean(d ** 2))) < 1.5 * _ft_noise_n(rec)


def test_calibrate_recovers_bed_friction_from_a_family_recording(
        family: tuple[str, Path, Path], tmp_path: Path) -> None:
    _, _, rec = family
    out = tmp_path / "lab.toml"
    # from the paper's scene: the replaying robot puts its own arm in the LWR4+'s place
    result = runner.invoke(app, ["calibrate", str(rec), "--fit", "target.mu", "--jobs", "1",
                                 "--out", str(out)])
    assert result.exit_code == 0, result.stderr
    scene = tomllib.loads(out.read_text())
    mu = scene["target"]["mu"]
    # measured 0.0060045 on both, 95 % [0.005985, 0.006025] (the tracker's noise on the
    # glide, +-0.3 %): within 2 % of the truth, far from the start (0.0085) or a bound
    assert abs(mu - MU_TRUE) < 0.02 * MU_TRUE, mu
    assert abs(mu - MU_DEFAULT) > 0.9 * (MU_DEFAULT - MU_TRUE)
    assert scene["arm"]["model"] == json.loads(
        load(rec, ()).metadata["run"]["scene_json"])["arm"]["model"]


def test_resimulate_a_family_recording_as_a_subprocess(
        family: tuple[str, Path, Path], tmp_path: Path) -> None:
    _, rec, _ = family
    sim = tmp_path / "sim.mcap"
    done = subprocess.run(
        [sys.executable, "-c", "from ffexp.cli import main; main()", "resimulate", str(rec),
         "--out", str(sim)], cwd=tmp_path, capture_output=True, text=True, timeout=300,
        check=False)
    assert done.returncode == 0, done.stderr
    assert "rms recorded - simulated: tcp 0, joints 0," in done.stdout
    assert sim.exists()


def test_recordings_of_two_families_are_one_error_line(
        family: tuple[str, Path, Path], tmp_path: Path) -> None:
    robot, rec, _ = family
    other = _record(tmp_path / "other", "ur-sim" if robot == "franka-sim" else "franka-sim",
                    [], timeout_s=0.6)
    out = tmp_path / "lab.toml"
    result = runner.invoke(app, ["calibrate", str(rec), str(other), "--fit", "target.mu",
                                 "--out", str(out), "--jobs", "1"])
    assert result.exit_code == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {other}: replayed by the "), lines
    assert not out.exists()


def test_a_recording_nobody_replays_is_one_error_line(tmp_path: Path) -> None:
    rec = run_file(PROTOCOL, ["run.timeout_s=0.6"], rig=RigChoice(driver="mock"),
                   out_dir=tmp_path / "mock").path
    out = tmp_path / "sim.mcap"
    result = runner.invoke(app, ["resimulate", str(rec), "--out", str(out),
                                 "--scene", str(ROOT / "data/scenes/paper.toml")])
    assert result.exit_code == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "'mock'" in lines[0], lines
    # the line says which robot types replay, the UR's and the Franka's among them
    assert "franka, franka-sim, fri1, sim, ur, ur-sim" in lines[0], lines
    assert not out.exists()
