"""The emulated FR3's world stepped lean (drivers/world/torque_step.py) is the same world as
stepped by ``SimWorld.advance``, bit for bit: every ``RobotState`` the controller reports,
the MuJoCo state and the world's own end state (its truth included), over holding, torque
loops, the target pushed into the tool (contact), a reflex and its recovery, a joint motion
of the robot's own controller, and with two physics steps per cycle; it draws no noise
(no F/T sensor reads), and a world it cannot step (a floating base) is stepped by the world.
The command's fields read in one unpacking sit where the protocol's layout puts them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from drivers.description.scene import load_scene
from drivers.errors import SimulationError
from drivers.franka import codec
from drivers.franka.emulate.controller import Fr3SimController
from drivers.world.torque_step import TorqueStepper, unfit
from drivers.world.world import SimWorld

ROOT = Path(__file__).resolve().parents[1]
FR3 = ROOT / "data/scenes/paper-fr3.toml"


def command(c: Fr3SimController, tau: np.ndarray, answer: bool = True,
            q_c: np.ndarray | None = None) -> np.void:
    cmd = np.zeros((), dtype=codec.ROBOT_COMMAND)
    cmd["message_id"] = c.message_id if answer else c.message_id - 1
    cmd["tau_J_d"] = tau
    if q_c is not None:
        cmd["q_c"] = q_c
    return codec.decode(codec.ROBOT_COMMAND, cmd.tobytes())


def twins(overrides: list[str]) -> tuple[Fr3SimController, Fr3SimController]:
    """The same scene's FR3 twice: stepped lean, and by ``SimWorld.advance``."""
    scene = load_scene(FR3, overrides)
    lean = Fr3SimController(SimWorld(scene, seed=0))
    plain = Fr3SimController(SimWorld(scene, seed=0), lean=False)
    assert lean.lean is not None and plain.lean is None
    return lean, plain


def run_both(pair: tuple[Fr3SimController, Fr3SimController], cycles: int,
             events: dict[int, str]) -> int:
    """Drive both controllers alike; every cycle their states, ``qpos`` and ``qvel`` must
    be the same bytes. Returns the cycles the tool touched the target."""
    rng = np.random.default_rng(3)
    lean = pair[0].lean
    assert lean is not None
    touching = 0
    for n in range(cycles):
        event = events.get(n, "")
        for c in pair:
            if event == "torque":
                c.start_motion()
            elif event == "push":  # the target slides into the tool
                c.world.set_target_velocity(-0.2, 0.05, 0.0)
            elif event == "reflex":
                c.inject_reflex()
            elif event == "recover":
                c.recover()
            elif event == "joints":  # the robot's joint impedance following q_c
                c.start_motion(codec.MoveMotionGeneratorMode.JOINT_POSITION,
                               codec.MoveControllerMode.JOINT_IMPEDANCE)
            elif event == "finish":
                c.finish_motion()
        tau = rng.normal(0.0, 0.2, 7) * [1.0, 1.0, 1.0, 1.0, 0.2, 0.2, 0.2]
        q_c = pair[0].world.arm_qpos + 2e-4 * np.sin(n / 50.0)
        for c in pair:  # some commands late, some missing
            c.step(command(c, tau, n % 17 != 0, q_c) if n % 31 else None)
        a, b = (c.state().tobytes() for c in pair)
        assert a == b, f"cycle {n}: " + ", ".join(
            f for f in codec.ROBOT_STATE.names  # type: ignore[union-attr]
            if codec.decode(codec.ROBOT_STATE, a)[f].tobytes()
            != codec.decode(codec.ROBOT_STATE, b)[f].tobytes())
        da, db = pair[0].world.data, pair[1].world.data
        assert da.qpos.tobytes() == db.qpos.tobytes(), f"cycle {n}"
        assert da.qvel.tobytes() == db.qvel.tobytes(), f"cycle {n}"
        touching += lean.touching
    return touching


def test_the_lean_world_is_the_worlds_own_bit_for_bit() -> None:
    pair = twins([])
    rng_before = pair[0].world.rng.bit_generator.state
    touching = run_both(pair, 3200, {50: "torque", 400: "push", 1400: "reflex",
                                     1500: "recover", 1600: "joints", 2300: "finish",
                                     2400: "torque", 2500: "push"})
    assert touching > 100  # the target pressed on the tool: the wrench and tau_ext
    a, b = (c.world for c in pair)
    assert a.cycle == b.cycle == 3200
    sa, sb = a.last_state, b.last_state  # the world's own state of the last cycle
    for name in ("jnt_pos_rad", "tcp_pose_m", "cmd_jnt_pos_rad", "jnt_trq_nm",
                 "ext_jnt_trq_nm", "ext_wrench_n_nm", "jacobian", "mass_matrix",
                 "gravity_nm"):
        assert np.array_equal(getattr(sa, name), getattr(sb, name)), name
    assert sa.mode == sb.mode and sa.warning == sb.warning
    assert sa.truth.in_contact == sb.truth.in_contact
    assert np.array_equal(sa.truth.contact_wrench, sb.truth.contact_wrench)
    for name, body in sa.truth.bodies.items():
        other = sb.truth.bodies[name]
        assert np.array_equal(body.pose, other.pose) and np.array_equal(body.twist, other.twist)
    # no F/T sensor reads: the world's generator drew nothing
    assert a.rng.bit_generator.state == rng_before
    assert b.rng.bit_generator.state != rng_before


def test_two_physics_steps_a_cycle_are_the_worlds_own_too() -> None:
    pair = twins(["physics.timestep=0.0005"])
    assert pair[0].world.substeps == 2
    run_both(pair, 600, {20: "torque", 300: "push"})


def test_a_world_the_lean_path_cannot_step_is_stepped_by_the_world() -> None:
    world = SimWorld(load_scene(ROOT / "data/scenes/free-flying.toml"), seed=0)
    why = unfit(world)
    assert why is not None and "floating base" in why
    with pytest.raises(ValueError, match="floating base"):
        TorqueStepper(world)
    c = Fr3SimController(world)
    assert c.lean is None
    c.start_motion()
    for _ in range(5):
        c.step(command(c, np.zeros(7)))
    assert world.cycle == 5 and c.success_rate == 1.0


def test_a_diverging_lean_world_raises() -> None:
    c = Fr3SimController(SimWorld(load_scene(FR3), seed=0))
    c.start_motion()
    c.step(command(c, np.zeros(7)))
    c.world.data.qvel[2] = np.nan  # a joint's speed gone bad between cycles
    with pytest.raises(SimulationError, match="physics diverged"):
        c.step(command(c, np.zeros(7)))


def test_the_torque_loops_fields_are_read_where_the_layout_puts_them() -> None:
    cmd = np.zeros((), dtype=codec.ROBOT_COMMAND)
    cmd["message_id"] = 2**40 + 7
    cmd["q_c"] = np.arange(7.0)
    cmd["motion_generation_finished"] = 1
    cmd["tau_J_d"] = np.arange(7.0) * -0.25 + 0.125
    cmd["torque_command_finished"] = 0
    fields = codec.COMMAND_TORQUES.unpack_from(cmd.tobytes())
    assert codec.COMMAND_TORQUES.size == codec.ROBOT_COMMAND.itemsize
    assert fields[0] == 2**40 + 7 and fields[1] == 1 and fields[9] == 0
    assert list(fields[2:9]) == (np.arange(7.0) * -0.25 + 0.125).tolist()
    cmd["torque_command_finished"] = 1
    assert codec.COMMAND_TORQUES.unpack_from(cmd.tobytes())[9] == 1
