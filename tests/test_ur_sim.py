"""The simulated UR5e: force mode and protective stop on the world, ffexp's URScript program's
semantics, the in-process lockstep UR against the same over RTDE, and Method I case I on
rigs/ur5e-sim.toml."""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from drivers.base.types import CartesianCommand
from drivers.description import load_scene
from drivers.errors import ConfigError
from drivers.ur import registers
from drivers.ur.config import UrSettings, UrSimConfig
from drivers.ur.driver import UrRobot
from drivers.ur.emulate.control import ForceModeCommand, UrArmControl
from drivers.ur.emulate.controller import STALE_CYCLES, UrSimController
from drivers.ur.emulate.lockstep import SimUrRobot
from drivers.ur.emulate.rtde_server import RtdeServer
from drivers.ur.errors import UrSafetyStopError
from drivers.ur.registers import Mode, ScriptState
from drivers.world.world import SimWorld

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "data/scenes/paper-ur5e.toml"


@pytest.fixture(scope="module")
def scene():  # type: ignore[no-untyped-def]
    return load_scene(SCENE)


def z_only() -> np.ndarray:
    return np.array([False, False, True, False, False, False])


def test_the_ur5e_scene_puts_its_tcp_where_the_lwr4s_is(scene) -> None:  # type: ignore[no-untyped-def]
    ur = SimWorld(scene)
    lwr = SimWorld(load_scene(ROOT / "data/scenes/paper.toml"))
    assert ur.scene.arm.description.name == "UR5e" and ur.data.qpos.shape[0] == 6 + 4
    np.testing.assert_allclose(ur.tcp_pose, lwr.tcp_pose, atol=2e-4)
    np.testing.assert_allclose(ur.layout.target_pos, lwr.layout.target_pos, atol=2e-4)


def test_force_mode_pushes_a_compliant_axis_against_the_damping_and_holds_the_others(
        scene) -> None:  # type: ignore[no-untyped-def]
    world = SimWorld(scene)
    arm = UrArmControl(world)
    start = world.tcp_pose.copy()
    lam = world.cart_inertia[2, 2]
    push = ForceModeCommand(start, z_only(), np.array([0.0, 0.0, 4.0, 0.0, 0.0, 0.0]),
                            np.full(6, 10.0), damping=0.0)
    for _ in range(25):
        world.advance(arm.command(push))
    v = arm.twist()
    # free space: Lambda a = F (no damping), within the arm's coupling and friction
    assert v[2] == pytest.approx(4.0 / lam * world.time, rel=0.25)
    moved = world.tcp_pose[:3, 3] - start[:3, 3]
    assert abs(moved[0]) > 1e-4 and abs(moved[1]) < 2e-4 and abs(moved[2]) < 2e-4
    # full damping, no force: the speed goes within a few cycles
    stop = ForceModeCommand(start, z_only(), np.zeros(6), np.full(6, 10.0), damping=1.0)
    for _ in range(5):
        world.advance(arm.command(stop))
    assert abs(arm.twist()[2]) < 0.2 * abs(v[2])


def test_force_mode_caps_the_compliant_axis_speed(scene) -> None:  # type: ignore[no-untyped-def]
    world = SimWorld(scene)
    arm = UrArmControl(world)
    cap = 0.02
    cmd = ForceModeCommand(world.tcp_pose.copy(), z_only(), np.array([0, 0, 30.0, 0, 0, 0]),
                           np.full(6, cap), damping=0.0)
    speeds = []
    for _ in range(60):
        world.advance(arm.command(cmd))
        speeds.append(arm.twist()[2])
    assert max(speeds) < 1.2 * cap and speeds[-1] > 0.8 * cap


def test_a_joint_beyond_its_speed_limit_is_a_protective_stop_that_holds_the_arm(
        scene) -> None:  # type: ignore[no-untyped-def]
    world = SimWorld(scene)
    arm = UrArmControl(world)
    spin = ForceModeCommand(world.tcp_pose.copy(),
                            np.array([False, False, False, False, False, True]),
                            np.array([0, 0, 0, 0, 0, 2.0]), np.full(6, 100.0), damping=0.0)
    for _ in range(500):
        world.advance(arm.command(spin))
        if arm.check_limits():
            break
    assert arm.stopped is not None and "joint 6" in arm.stopped and "speed" in arm.stopped
    for _ in range(100):
        world.advance(arm.command(spin))  # ignored: held
    assert abs(world.data.qvel[5]) < 0.05


def test_the_program_holds_on_a_stale_sequence_and_restarts_after_an_end(scene) -> None:  # type: ignore[no-untyped-def]
    ctl = UrSimController(SimWorld(scene))
    record = {registers.SEQ: 1, registers.MODE: int(Mode.SERVO),
              **dict(zip(registers.POSE, registers.pose_vector(ctl.world.tcp_pose),
                         strict=True))}
    ctl.take(record)
    out = ctl.step()
    assert out[registers.APPLIED_SEQ] == 1 and out[registers.SCRIPT_STATE] == ScriptState.RUNNING
    for _ in range(STALE_CYCLES):
        out = ctl.step()
    assert out[registers.SCRIPT_STATE] == ScriptState.HELD_STALE
    ctl.take({registers.SEQ: 2, registers.MODE: int(Mode.END)})
    assert ctl.step()[registers.SCRIPT_STATE] == ScriptState.ENDED
    ctl.take({registers.SEQ: 3, registers.MODE: int(Mode.SERVO)})
    out = ctl.step()
    assert out[registers.SCRIPT_STATE] == ScriptState.RUNNING and out[registers.APPLIED_SEQ] == 3


def _drive(robot: UrRobot, cycles: int, push_n: float = 2.0) -> list[tuple[np.ndarray, ...]]:
    """Push along Z with ``push_n`` in force mode (the paper's stiffness: Y, Z, rot-X
    compliant); each cycle's time, pose, joints and wrench."""
    robot.connect()
    got = []
    try:
        for k, state in enumerate(robot.measurements()):
            got.append((np.array(state.time_ns), state.tcp_pose_m.copy(),
                        state.joint_pos_rad.copy(), np.array(state.ext_wrench_n_nm)))
            if k == cycles:
                break
            cmd = CartesianCommand(pose_m=state.tcp_pose_m.copy(),
                                   stiffness_npm_nmprad=np.array([5000, 0, 0, 0, 300, 300.0]),
                                   wrench_n_nm=np.array([0, 0.1 * np.sin(k / 9), push_n, 0, 0, 0]))
            robot.send(cmd)
    finally:
        robot.close()
    return got


def test_the_in_process_ur_equals_the_same_run_over_rtde_in_lockstep(scene) -> None:  # type: ignore[no-untyped-def]
    cfg = UrSimConfig(truth=False)
    inproc = _drive(SimUrRobot(SimWorld(scene, seed=3), cfg), 150)
    ctl = UrSimController(SimWorld(scene, seed=3))
    with RtdeServer(ctl.step, ctl.take, host="127.0.0.1", port=0, pacing="lockstep",
                    base_hz=500.0) as srv:
        settings = UrSettings(robot_ip="127.0.0.1", rtde_port=srv.port, script="installed",
                              cycle_timeout_s=5.0)
        wire = _drive(UrRobot(settings), 150)
    assert len(inproc) == len(wire) == 151
    moved = inproc[-1][1][:3, 3] - inproc[0][1][:3, 3]
    assert abs(moved[0]) > 1e-3  # it moved along TCF Z (world x)
    for a, b in zip(inproc, wire, strict=True):
        for x, y in zip(a, b, strict=True):
            np.testing.assert_array_equal(x, y)


def test_a_protective_stop_ends_the_in_process_run_naming_the_controller(scene) -> None:  # type: ignore[no-untyped-def]
    robot = SimUrRobot(SimWorld(scene), UrSimConfig(compliant_speed_limits_mps_radps=(
        1, 1, 1, 100, 100, 100)), where="rigs/x.toml: robot")
    robot.connect()
    with pytest.raises(UrSafetyStopError, match=r"127\.0\.0\.1:30004.*protective_stopped"):
        for state in robot.measurements():
            robot.send(CartesianCommand(pose_m=state.tcp_pose_m.copy(),
                                        stiffness_npm_nmprad=np.array([5000.0] * 5 + [0.0]),
                                        wrench_n_nm=np.array([0, 0, 0, 0, 0, 2.0])))
    robot.close()


def test_the_ur_rigs_load_and_a_wrench_sensor_needs_a_ur(tmp_path: Path) -> None:
    from drivers.rig import load_rig

    assert [load_rig(ROOT / f"rigs/ur5e-{n}.toml").robot.type for n in ("sim", "emulator", "lab")] \
        == ["ur-sim", "ur", "ur"]
    bad = tmp_path / "bad.toml"
    bad.write_text('[robot]\ntype = "sim"\n[ft]\ntype = "ur-wrench"\n')
    with pytest.raises(ConfigError, match=r"bad\.toml.*ur-wrench.*robot\.type 'ur'"):
        load_rig(bad)


def test_the_emulated_rig_refuses_a_scene_whose_arm_is_not_a_ur() -> None:
    from drivers.emulate.session import EmulatedRig, EmulatedRigSettings

    lwr = load_scene(ROOT / "data/scenes/paper.toml")
    with pytest.raises(ConfigError, match=r"^--robot: ur5e: the scene \(paper\) has "
                                          r"arm\.model 'lwr4', not 'ur5e'$"):
        EmulatedRig(EmulatedRigSettings(scene=lwr, robot="ur5e", listen=("127.0.0.1", 0),
                                        netft_port=None)).open()


@pytest.mark.slow
def test_method1_case1_runs_to_an_end_on_the_ur_sim_rig(tmp_path: Path) -> None:
    from ffexp.cli import app
    from ffexp.recording.reader import load

    result = CliRunner().invoke(app, ["run", str(ROOT / "protocols/method1_case1.toml"),
                                      "--rig", str(ROOT / "rigs/ur5e-sim.toml"),
                                      "--out", str(tmp_path)])
    assert result.exit_code in (0, 4), result.output  # aligned, or timed out
    (path,) = tmp_path.glob("*.mcap")
    rec = load(path)
    assert rec.complete
    assert any(m.get("driver") == "ur-sim" for m in rec.metadata.values())
    assert len(rec.topic("/robot/ur")) == len(rec.topic("/robot/state")) > 1000


def test_the_pose_vector_and_matrix_are_scipys_rotation_vector_and_rodrigues() -> None:
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(5)
    turns = [*Rotation.random(200, random_state=rng),
             Rotation.from_rotvec([np.pi - 1e-9, 0, 0]), Rotation.from_rotvec([0, 0, np.pi]),
             Rotation.from_rotvec([1e-14, 0, 0]), Rotation.identity(),
             Rotation.from_rotvec([0, 3.1, 0.2])]
    for rot in turns:
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = rot.as_matrix(), rng.normal(size=3)
        vec = registers.pose_vector(pose)
        np.testing.assert_array_equal(vec[:3], pose[:3, 3])
        # the same rotation (a rotation vector of angle pi is either sign)
        np.testing.assert_allclose(Rotation.from_rotvec(vec[3:]).as_matrix(), pose[:3, :3],
                                   atol=1e-12)
        assert np.linalg.norm(vec[3:]) <= np.pi + 1e-12
        if np.linalg.norm(vec[3:]) < np.pi - 1e-6:
            np.testing.assert_allclose(vec[3:], rot.as_rotvec(), atol=1e-12)
        np.testing.assert_allclose(registers.pose_matrix(vec), pose, atol=1e-12)


def test_the_emulated_rigs_disconnect_fault_ends_the_ur_driver_naming_the_address(
        scene) -> None:  # type: ignore[no-untyped-def]
    from drivers.emulate.session import EmulatedRig, EmulatedRigSettings
    from drivers.errors import LinkLostError

    settings = EmulatedRigSettings(scene=scene, robot="ur5e", listen=("127.0.0.1", 0),
                                   netft_port=None, pacing="lockstep",
                                   family_faults={"disconnect_after": 20})
    with EmulatedRig(settings) as rig:
        assert rig.served is not None
        port = rig.served.address[1]
        done = threading.Event()  # the rig serves in its own thread, as ffexp emulate's
        server = threading.Thread(target=rig.serve, args=(done.is_set,), daemon=True)
        server.start()
        try:
            robot = UrRobot(UrSettings(robot_ip="127.0.0.1", rtde_port=port,
                                       script="installed", cycle_timeout_s=5.0))
            robot.connect()
            seen = 0
            with pytest.raises(LinkLostError, match=rf"127\.0\.0\.1:{port}"):
                for state in robot.measurements():
                    seen += 1
                    robot.send(CartesianCommand(pose_m=state.tcp_pose_m.copy()))
            robot.close()
        finally:
            done.set()
            server.join(10.0)
    assert seen == 20


def test_the_ur5e_scene_file_is_the_papers_with_the_ur5e_overrides(scene) -> None:  # type: ignore[no-untyped-def]
    from drivers.description.ur5e import PAPER_SCENE_OVERRIDES

    assert load_scene(ROOT / "data/scenes/paper.toml", PAPER_SCENE_OVERRIDES) == scene
    assert load_scene(ROOT / "data/scenes/paper.toml").arm.model == "lwr4"  # the default
    with pytest.raises(ConfigError, match=r"arm\.q_init has 7 values; the UR5e"):
        load_scene(ROOT / "data/scenes/paper.toml", ("arm.model='ur5e'",))


def test_the_sim_tracker_judges_a_ur_sim_run_without_ground_truth(tmp_path: Path) -> None:
    import json

    from mcap.reader import make_reader

    from ffexp.experiment import RigChoice, run_file

    rig = RigChoice(ROOT / "rigs/ur5e-sim.toml", ("robot.truth=false", "tracker.type='sim'"))
    result = run_file(ROOT / "protocols/method1_case2.toml", ["run.timeout_s=1.0"], rig=rig,
                      out_dir=tmp_path)
    verdicts, poses = [], 0
    with result.path.open("rb") as fh:
        for _, channel, message in make_reader(fh).iter_messages(
                topics=["/alignment/verdict", "/target/pose"]):
            if channel.topic == "/target/pose":
                poses += 1
            else:
                verdicts.append(json.loads(message.data))
    assert poses >= 40  # the camera model's 50 frames a second
    assert verdicts[0]["source"] == "tracker" and verdicts[-1]["final"]
    assert verdicts[-1]["truth"] == ""  # no ground truth on this rig
