"""The simulated UR's cycle against its plain forms: the program's registers latched at once
(the in-process link) or name by name (the RTDE emulator), the force-mode law's kept axis
masses and twist against a fresh law's, and the end state read once for the outputs, the next
command and the truth."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from drivers.base.types import CartesianCommand
from drivers.description import load_scene
from drivers.ur import registers
from drivers.ur.emulate.control import ForceModeCommand, UrArmControl
from drivers.ur.emulate.controller import UrSimController
from drivers.world.world import SimWorld

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "data" / "scenes" / "paper-ur5e.toml"


def bits(a: object) -> list[int]:
    return np.ascontiguousarray(a, dtype=np.float64).view(np.int64).ravel().tolist()


def _record(k: int, pose: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    from drivers.ur.rtde.fields import Recipe
    from drivers.ur.rtde.variables import INPUTS

    recipe = Recipe(2, registers.INPUT_NAMES, tuple(INPUTS[n] for n in registers.INPUT_NAMES))
    record = recipe.empty()
    target = pose.copy()
    target[:3, 3] += rng.normal(0.0, 0.002, 3)
    stiffness = np.array([5000.0, 5000.0, 0.0 if k % 7 else 5000.0, 300.0, 300.0, 300.0])
    cmd = CartesianCommand(target, stiffness, np.full(6, 0.7), rng.normal(0.0, 5.0, 6))
    registers.fill_command(record, k + 1, None if k % 11 == 10 else cmd, pose,
                           stiffness_max=200.0, speed_limits=np.full(6, 0.1),
                           deviation_limits=np.full(6, 0.1), damping=0.005 * (k % 3),
                           gain_scaling=1.0 + 0.1 * (k % 2), lookahead_s=0.1, servo_gain=300)
    return record


def test_registers_latched_at_once_run_the_program_as_name_by_name() -> None:
    worlds = [SimWorld(load_scene(SCENE), seed=3) for _ in range(2)]
    at_once, by_name = (UrSimController(w) for w in worlds)
    rng = np.random.default_rng(1)
    for k in range(60):
        record = _record(k, worlds[0].tcp_pose, rng)
        at_once.take_program_inputs(record.item())
        by_name.take({n: record[n].item() for n in registers.INPUT_NAMES})
        assert at_once.inputs == by_name.inputs
        a, b = at_once.step(), by_name.step()
        assert a.keys() == b.keys()
        for name in a:
            assert bits(a[name]) == bits(b[name]), name


def test_an_input_outside_the_program_is_kept_beside_its_registers() -> None:
    controller = UrSimController(SimWorld(load_scene(SCENE), seed=3))
    assert controller.inputs[registers.SEQ] == 0  # zero until written
    controller.take({"input_double_register_0": 1.5, registers.SEQ: 4})
    assert controller.inputs["input_double_register_0"] == 1.5
    assert controller.inputs[registers.SEQ] == 4


def test_the_kept_axis_masses_give_a_fresh_laws_command() -> None:
    # the arm moves under force mode, so the world's Cartesian inertia changes now and
    # then; a law made anew every cycle (nothing kept) commands the same bits
    world = SimWorld(load_scene(SCENE), seed=4)
    law = UrArmControl(world)
    changes, last = 0, world.cart_inertia
    for k in range(300):
        pose = world.tcp_pose.copy()
        compliant = np.array([False, False, True, k % 50 < 25, False, False])
        wrench = np.array([0.0, 0.0, 20.0 * np.sin(k / 20), 0.5, 0.0, 0.0])
        cmd = ForceModeCommand(pose, compliant, wrench, np.full(6, 0.05 + 0.01 * (k % 3)),
                               0.01 * (k % 4), 1.0)
        if k % 2:  # the twist read first at this state (as the outputs read it): kept
            assert bits(law.twist()) == bits(UrArmControl(world).twist())
        got = law.command(cmd)
        want = UrArmControl(world).command(cmd)
        assert bits(got.tcp_wrench_n_nm) == bits(want.tcp_wrench_n_nm)
        assert bits(got.cart_stiffness_npm_nmprad) == bits(want.cart_stiffness_npm_nmprad)
        world.advance(got)
        changes += world.cart_inertia is not last
        last = world.cart_inertia
    assert changes > 3  # the inertia did change under the law


def test_the_end_state_is_read_once_a_cycle() -> None:
    world = SimWorld(load_scene(SCENE), seed=5)
    controller = UrSimController(world)
    controller.take_program_inputs(_record(0, world.tcp_pose, np.random.default_rng(0)).item())
    controller.step()
    state = world.last_state
    assert controller._state is state  # the outputs' state, still the world's
    truth = state.truth
    controller.step()  # the next command read it; the cycle's end made a new one
    assert world.last_state is not state and state.truth is truth


def _rodrigues(vector: np.ndarray) -> np.ndarray:
    """UR's pose 6-vector as a 4x4 pose, written into an identity (the plain form)."""
    pose = np.eye(4)
    rx, ry, rz = (float(v) for v in vector[3:6])
    angle = math.sqrt(rx * rx + ry * ry + rz * rz)
    if angle < 1e-12:
        rot = [[1.0, -rz, ry], [rz, 1.0, -rx], [-ry, rx, 1.0]]
    else:
        kx, ky, kz = rx / angle, ry / angle, rz / angle
        c, s = math.cos(angle), math.sin(angle)
        v = 1.0 - c
        rot = [[c + kx * kx * v, kx * ky * v - kz * s, kx * kz * v + ky * s],
               [ky * kx * v + kz * s, c + ky * ky * v, ky * kz * v - kx * s],
               [kz * kx * v - ky * s, kz * ky * v + kx * s, c + kz * kz * v]]
    pose[:3, :3] = rot
    pose[:3, 3] = vector[:3]
    return pose


def test_pose_matrix_is_rodrigues_into_an_identity_bit_for_bit() -> None:
    rng = np.random.default_rng(9)
    out = np.full((4, 4), np.nan)
    for k in range(3000):
        v = rng.normal(size=6) * (1e-13 if k % 10 == 0 else 1.0)
        want = _rodrigues(v)
        assert bits(registers.pose_matrix(v)) == bits(want)
        assert registers.pose_matrix(v, out) is out and bits(out) == bits(want)


def test_a_hold_and_a_command_fill_the_registers_as_the_rule_says() -> None:
    from drivers.ur.rtde.fields import Recipe
    from drivers.ur.rtde.variables import INPUTS

    recipe = Recipe(2, registers.INPUT_NAMES, tuple(INPUTS[n] for n in registers.INPUT_NAMES))
    record = recipe.empty()
    rng = np.random.default_rng(4)
    speed, deviation = np.full(6, 0.1), np.array([0.01, 0.02, 0.03, 0.1, 0.2, 0.3])
    for k in range(200):
        pose = _rodrigues(rng.normal(size=6))
        stiffness = np.where(rng.random(6) < 0.5, 100.0, 3000.0)
        cmd = None if k % 5 == 0 else CartesianCommand(pose, stiffness, np.full(6, 0.7),
                                                       rng.normal(size=6))
        mode = registers.fill_command(record, k, cmd, pose, stiffness_max=200.0,
                                      speed_limits=speed, deviation_limits=deviation,
                                      damping=0.1, gain_scaling=1.0, lookahead_s=0.1,
                                      servo_gain=300.0)
        compliant = np.zeros(6, bool) if cmd is None else stiffness <= 200.0
        assert mode == (registers.Mode.HOLD if cmd is None else registers.Mode.FORCE
                        if compliant.any() else registers.Mode.SERVO)
        assert int(record[registers.SELECTION]) == sum(1 << i for i in range(6) if compliant[i])
        wrench = [float(record[n]) for n in registers.WRENCH]
        assert bits(wrench) == bits(np.where(compliant, 0.0 if cmd is None else
                                             cmd.wrench_n_nm, 0.0))
        limits = [float(record[n]) for n in registers.LIMITS]
        assert limits == np.where(compliant, speed, deviation).tolist()
        assert bits([float(record[n]) for n in registers.POSE]) == bits(
            registers.pose_vector(pose))
