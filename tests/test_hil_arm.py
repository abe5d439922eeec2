"""The carrier as an arm (``carrier.model = "arm"``, docs/hil.md): both arms in one MuJoCo
world, the mock-up behind a simulated F/T sensor on the carrier's flange, the carrier loop
commanding the arm through inverse kinematics. Its kinematics against finite differences,
its tracking of a commanded pose, the rendered body under a known wrench against the
closed form, and the impact against the delayed unilateral contact."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from drivers import registry
from drivers.carrier.armbench import ArmServo, run_arm_impact
from drivers.carrier.bench import Impact
from drivers.carrier.body import rotation_exp, rotation_log
from drivers.carrier.plant import arm_layout
from drivers.description.scene import Scene, inertia_tensor, load_scene
from ffexp.hil.analysis import analyze_recording
from ffexp.hil.protocol import load_hil_protocol
from ffexp.hil.record import record_impact, run_protocol
from ffexp.recording import load

ROOT = Path(__file__).resolve().parents[1]
ZERO_G = ROOT / "data/scenes/zero-g.toml"
QUIET = ("carrier.model='arm'", "ft_sensor.noise_std=[0.0, 0.0]")


def scene(*sets: str) -> Scene:
    return load_scene(ZERO_G, (*QUIET, *sets))


def test_kinematics_jacobian_and_inverse() -> None:
    """The Jacobian is the forward kinematics' derivative; the inverse reaches a pose."""
    s = scene()
    layout = arm_layout(s, 0.002, 0.0)
    chain, q0 = layout.carrier, layout.carrier_q0
    pose, jac = chain.jacobian(q0)
    eps = 1e-7
    for i in range(len(q0)):
        dq = np.zeros_like(q0)
        dq[i] = eps
        moved = chain.pose(q0 + dq)
        assert np.allclose((moved[:3, 3] - pose[:3, 3]) / eps, jac[:3, i], atol=1e-6)
        assert np.allclose(rotation_log(moved[:3, :3] @ pose[:3, :3].T) / eps, jac[3:, i],
                           atol=1e-6)
    target = pose.copy()
    target[:3, 3] += (0.03, -0.02, 0.01)
    target[:3, :3] = rotation_exp(np.array([0.05, 0.0, -0.08])) @ target[:3, :3]
    q = chain.solve_ik(target, q0)
    assert np.allclose(chain.pose(q), target, atol=1e-9)
    # the start: the mock-up's centre where the layout puts the rendered body, level
    assert np.allclose(chain.pose(q0)[:3, 3], layout.centre_m, atol=1e-9)
    assert np.allclose(chain.pose(q0)[:3, :3], np.eye(3), atol=1e-9)


def test_the_arm_tracks_a_commanded_pose() -> None:
    """A ramp of the mock-up's centre and a turn, sent each cycle as servoJ targets: at
    the end the arm stands at the pose (its servo has no steady-state error)."""
    s = scene()
    layout = arm_layout(s, 0.3, 0.0)
    world = registry.carrier_world(s, layout)
    cycle = s.carrier.cycle_s
    servo = ArmServo(layout.carrier, layout.carrier_q0, layout.centre_m, cycle)
    state = world.start()
    direction = np.array([1.0, 1.0, -0.5]) / 1.5
    axis = np.array([0.0, 0.0, 1.0])
    ramp_s, speed, turn_rate = 0.2, 0.1, 0.25
    lags = []
    for n in range(250):
        t = min(n * cycle, ramp_s)
        moving = n * cycle < ramp_s
        servo.measure(state.carrier_q, state.carrier_qd)
        pos = direction * speed * t
        servo.send(pos, direction * speed * moving, rotation_exp(axis * turn_rate * t),
                   axis * turn_rate * moving)
        state = world.step(servo.q_target, servo.qd_target, layout.chaser_q0,
                           np.zeros(layout.chaser.arm.joints))
        lags.append(float(np.linalg.norm(servo.at(0.0)[0] - pos)))
    servo.measure(state.carrier_q, state.carrier_qd)
    pos, rot, twist, _ = servo.at(0.0)
    assert np.linalg.norm(pos - direction * speed * ramp_s) < 1e-6
    assert np.linalg.norm(rotation_log(rot) - axis * turn_rate * ramp_s) < 1e-5
    assert np.linalg.norm(twist) < 1e-4
    assert 0.0 < max(lags) < speed * 0.02  # it follows, within 20 ms of the ramp


def _pushed(push: tuple[float, float, np.ndarray] | None) -> tuple[np.ndarray, np.ndarray]:
    """Per carrier cycle: the rendered body's momentum and angular momentum, the chaser
    far away (no contact), a wrench applied to the mock-up from 0.1 to 0.2 s."""
    s = scene("carrier.energy_gain_limit=1e9")
    layout = arm_layout(s, 0.3, 0.0)
    world = registry.carrier_world(s, layout)
    if push is not None:
        world = type(world)(s, layout, push=push)
    trace = run_arm_impact(s, Impact(speed_mps=0.01, gap_m=0.3, duration_s=0.5), layout,
                           world)
    assert trace.hold is None and trace.contact_start_s is None
    rows = np.asarray(trace.cycle)
    inertia = inertia_tensor(s.target.mass, s.target.size, s.target.inertia)
    momentum = rows[:, 6:9] * s.target.mass
    angular = np.array([rotation_exp(r[3:6]) @ inertia @ rotation_exp(r[3:6]).T @ r[9:12]
                        for r in rows])
    return momentum, angular


def test_without_the_chaser_the_rendered_body_stays_put() -> None:
    momentum, angular = _pushed(None)
    assert np.abs(momentum).max() < 1e-6
    assert np.abs(angular).max() < 1e-7


def test_a_force_pulse_gives_its_impulse_and_the_momentum_is_kept() -> None:
    """``p = F dt`` (closed form) within 2 % of its size; constant after the pulse."""
    force = np.array([3.0, -2.0, 1.0])
    momentum, angular = _pushed((0.1, 0.2, np.concatenate((force, np.zeros(3)))))
    impulse = force * 0.1
    size = float(np.linalg.norm(impulse))
    after = momentum[125:]  # from 0.25 s
    assert np.linalg.norm(after[0] - impulse) < 0.02 * size
    assert np.abs(after - after[0]).max() < 1e-3 * size
    assert np.abs(angular).max() < 0.02 * size * 0.1  # no turn from a force at the centre


def test_a_torque_pulse_gives_its_angular_impulse() -> None:
    """``L = tau dt`` within 5 % of its size (the mock-up's own inertia compensated)."""
    torque = np.array([0.2, -0.1, 0.3])
    _, angular = _pushed((0.1, 0.2, np.concatenate((np.zeros(3), torque))))
    impulse = torque * 0.1
    size = float(np.linalg.norm(impulse))
    assert np.linalg.norm(angular[125] - impulse) < 0.05 * size
    assert np.abs(angular[125:] - angular[125]).max() < 0.01 * size


@pytest.mark.parametrize("stiffness", [5e3, 2e4])
def test_the_arm_carrier_follows_the_delayed_unilateral_contact(
        tmp_path: Path, stiffness: float) -> None:
    """With the arm as carrier the restitution is within 15 % of the delayed contact's at
    the measured delay (the arm's response included); each extra cycle adds about one
    cycle of measured delay and energy."""
    proto = load_hil_protocol(ROOT / "protocols/hil_impact.toml")
    results = []
    for cycles in (0, 2):
        run = run_protocol(proto, ("carrier.model='arm'", f"contact.stiffness={stiffness}",
                                   f"carrier.extra_delay_cycles={cycles}"))
        a = analyze_recording(load(record_impact(run, tmp_path / f"{stiffness}-{cycles}.mcap")))
        assert a["carrier_held"] is None
        wn_tau = math.sqrt(stiffness / a["effective_mass_kg"]) * a["loop_delay_s"]
        assert wn_tau <= 0.3
        assert a["restitution"] == pytest.approx(a["reference_restitution"], rel=0.15)
        assert a["restitution"] > a["true_restitution"]
        results.append(a)
    assert results[1]["restitution"] > results[0]["restitution"]
    assert results[1]["loop_delay_s"] - results[0]["loop_delay_s"] == pytest.approx(
        2 * 0.002, rel=0.2)
