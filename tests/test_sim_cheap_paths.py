"""The world's cheap per-cycle paths give the very values of the plain ones, bit for bit.

Block-drawn F/T noise against per-block draws, the friction level written in
place against :meth:`JointFriction.dry_level_nm`, the lazily built end state
against one read at once, repeated gains against fresh arrays, MuJoCo's sensor
history against a copy of the sensor after each physics step, and the KRC's
limit and clip checks against their numpy forms.
"""

from __future__ import annotations

import copy
import math
import pickle
from pathlib import Path

import mujoco
import numpy as np
import pytest

from drivers.base.placement import placement, placement_at_mouth
from drivers.base.types import ApplyStatus, CartesianCommand
from drivers.description import load_scene
from drivers.description.scene import FtSensorSettings
from drivers.errors import SimulationError
from drivers.fri.emulate.krc import software_limit_error
from drivers.fri.emulate.lockstep import SimRobot
from drivers.world import ArmCommand, SimWorld
from drivers.world.arm import ArmMode, ArmState
from drivers.world.friction import JointFriction
from drivers.world.ftsensor import NOISE_BLOCK, FtSensorModel

ROOT = Path(__file__).resolve().parent.parent
PAPER = ROOT / "data" / "scenes" / "paper.toml"
FIELDS = ("jnt_pos_rad", "tcp_pose_m", "cmd_jnt_pos_rad", "cmd_cart_pose_m", "jnt_trq_nm",
          "ext_jnt_trq_nm", "ext_wrench_n_nm", "jacobian", "mass_matrix", "gravity_nm")


def _reference_ft(settings: FtSensorSettings, seed: int, r: np.ndarray,
                  blocks: list[np.ndarray]) -> list[np.ndarray]:
    """The sensor model as it was: fresh draws per block (module docstring of ftsensor)."""
    rng = np.random.default_rng(seed)
    model = FtSensorModel(settings, np.random.default_rng(seed), r)  # for its constants
    b_f, b_t = settings.bias_std
    bias = rng.normal(0.0, 1.0, 6) * np.array([b_f] * 3 + [b_t] * 3)
    drift = np.zeros(6)
    out = []
    for raw in blocks:
        gauss = rng.standard_normal((raw.shape[0], 12))
        gauss *= model._scale
        d = np.add.accumulate(gauss[:, :6], axis=0)
        d += drift
        drift = d[-1].copy()
        w = gauss[:, 6:] - raw
        w += d
        w += bias
        np.clip(w, -model._range, model._range, out=w)
        w = w @ model._xform
        w -= np.zeros(6)
        w *= model._inv_res
        np.rint(w, out=w)
        w *= model._res
        out.append(w)
    return out


def test_block_drawn_noise_equals_per_block_draws() -> None:
    settings = FtSensorSettings(delay_s=0.0)  # the reference has no delay line
    r = np.array([0.0, 0.0, -0.05])
    gen = np.random.default_rng(7)
    sizes = [5, 1, 3, 0, 700, 5, NOISE_BLOCK, 2, NOISE_BLOCK + 3] + [5] * 300
    blocks = [gen.normal(0.0, 5.0, (n, 6)) for n in sizes]
    model = FtSensorModel(settings, np.random.default_rng(11), r)
    got = [model.process(b, 0).wrench for b in blocks if b.shape[0]]
    want = _reference_ft(settings, 11, r, [b for b in blocks if b.shape[0]])
    assert len(got) == len(want)
    for g, w in zip(got, want, strict=True):
        assert g.tobytes() == w.tobytes()


def test_tare_still_subtracts_after_block_draws() -> None:
    model = FtSensorModel(FtSensorSettings(noise_std=(0.0, 0.0), drift_density=(0.0, 0.0)),
                          np.random.default_rng(3), np.zeros(3))
    raw = np.tile([[0.0, 0.0, 4.0, 0.0, 0.0, 0.0]], (5, 1))
    before = model.process(raw, 0).wrench
    model.tare_offset = model.tare_offset + before[-1]
    after = model.process(raw, 0).wrench
    np.testing.assert_allclose(after, 0.0, atol=1e-12)
    model.tare_offset = np.zeros(6)
    assert model.process(raw, 0).wrench.tobytes() == before.tobytes()


@pytest.mark.parametrize("shape", [2.0, 1.0, 1.5])
def test_friction_level_in_place_equals_dry_level(shape: float) -> None:
    f = JointFriction(static_nm=np.linspace(1.0, 3.0, 7), coulomb_nm=np.linspace(0.5, 2.0, 7),
                      viscous_nmsprad=np.full(7, 0.1), stribeck_radps=np.full(7, 0.02),
                      shape=shape)
    out = np.zeros(7)
    for v in np.random.default_rng(5).normal(0.0, 0.05, (200, 7)):
        f.apply_into(v, out)
        assert out.tobytes() == f.dry_level_nm(v).tobytes()
    edge = np.array([0.02 * 27.0, -0.02 * 27.4, 0.02 * 40.0, -0.02 * 40.0001, 0.02 * 45.0,
                     1e200, -np.inf])  # around the clip at 40 Stribeck speeds, huge
    for v in (edge, -edge, np.full(7, 1e300), np.zeros(7), np.full(7, -0.0)):
        f.apply_into(v, out)
        assert out.tobytes() == f.dry_level_nm(v).tobytes()


def _script(i: int, p0: np.ndarray) -> ArmCommand | None:
    """Approach and press into the funnel, the gains given again and again (same values)."""
    if i % 4 == 0:
        return None
    p = p0.copy()
    p[:3, 3] += 0.045 * p0[:3, 2] * min(1.0, i / 150)
    return ArmCommand(cart_pose_m=p,
                      tcp_wrench_n_nm=np.array([0.0, 0.1 * math.sin(i / 9), 1.0, 0.0, 0.0, 0.0]),
                      cart_stiffness_npm_nmprad=np.array([5000.0, 0.0, 0.0, 0.0, 300.0, 300.0]),
                      cart_damping_ratio=np.array([0.7, 0.0, 0.0, 0.0, 0.7, 0.7]))


def _values(s: ArmState) -> list[bytes]:
    out = [repr((s.cycle, s.time_ns, int(s.mode), int(s.warning))).encode()]
    out += [np.asarray(getattr(s, name)).tobytes() for name in FIELDS]
    t = s.truth
    for name, body in sorted(t.bodies.items()):
        out += [name.encode(), body.pose.tobytes(), body.twist.tobytes(),
                repr(body.mass_kg).encode()]
    for name, frame in sorted(t.sites.items()):
        out += [name.encode(), frame.tobytes()]
    out += [t.contact_wrench.tobytes(), t.tcp_twist.tobytes(), repr(t.in_contact).encode()]
    return out


def test_lazy_end_state_equals_reading_it_at_once() -> None:
    cycles = 320
    a = SimWorld(load_scene(PAPER), seed=4)
    b = SimWorld(load_scene(PAPER), seed=4)
    p0 = a.last_state.tcp_pose_m.copy()
    read_now = [_values(a.last_state)]
    for i in range(cycles):
        read_now.append(_values(a.step(_script(i, p0))))
    # b: the same cycles; states held and read late, in another order, some never
    held: list[ArmState | None] = [b.last_state]
    for i in range(cycles):
        b.advance(_script(i, p0))
        s: ArmState | None = b.last_state
        assert s is not None
        if i % 4 == 0:
            _ = s.truth  # one group first (it needs the Jacobian too)
        elif i % 4 == 1:
            _ = s.jnt_pos_rad  # the joints only, the rest after later cycles
        elif i % 4 == 2:
            s = None  # nobody reads this cycle
        held.append(s)  # (i % 4 == 3: nothing read now, all of it later)
    assert any(s is not None and s.truth.in_contact for s in held)
    for want, s in zip(read_now, held, strict=True):
        if s is not None:
            assert _values(s) == want


def test_state_copies_and_pickles_are_plain_states() -> None:
    w = SimWorld(load_scene(PAPER), seed=2)
    s = w.step(ArmCommand(tcp_wrench_n_nm=np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0])))
    c = copy.deepcopy(s)
    p = pickle.loads(pickle.dumps(s))
    w.step()
    for other in (c, p):
        assert type(other) is ArmState
        assert _values(other) == _values(s)


def test_target_velocity_keeps_the_state_of_the_cycle() -> None:
    a = SimWorld(load_scene(PAPER), seed=2)
    b = SimWorld(load_scene(PAPER), seed=2)
    a.step()
    b.step()
    want = _values(a.last_state)
    b.set_target_velocity(0.01, 0.0, 0.0)  # nobody held the state: it is kept anyway
    assert _values(b.last_state) == want


def test_repeated_gains_equal_fresh_ones() -> None:
    a = SimWorld(load_scene(PAPER), seed=1)
    b = SimWorld(load_scene(PAPER), seed=1)
    k = np.array([9000.0, 0.0, 10.0, 0.0, 300.0, 300.0])  # clipped: warned every cycle
    d = np.array([0.7, 0.0, 0.0, 0.0, 0.7, 0.7])
    pose = a.last_state.tcp_pose_m.copy()
    pose[2, 3] -= 0.01
    same = ArmCommand(cart_stiffness_npm_nmprad=k, cart_damping_ratio=d, cart_pose_m=pose,
                      tcp_wrench_n_nm=np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0]))
    joints = ArmCommand(mode=ArmMode.JOINT_IMPEDANCE)
    back = ArmCommand(mode=ArmMode.CART_IMPEDANCE)
    for i in range(70):
        kk = k.copy() if i < 30 else k * 0.5
        fresh = ArmCommand(cart_stiffness_npm_nmprad=kk, cart_damping_ratio=d.copy(),
                           cart_pose_m=pose.copy(),
                           tcp_wrench_n_nm=np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0]))
        if i >= 30:
            same.cart_stiffness_npm_nmprad = k * 0.5
        if i in (40, 41):  # to a joint mode and back: the same pose again after it
            fresh = same = joints if i == 40 else back
        sa, sb = a.step(fresh), b.step(same)
        if i == 41:
            same = ArmCommand(cart_stiffness_npm_nmprad=k * 0.5, cart_damping_ratio=d,
                              cart_pose_m=pose, tcp_wrench_n_nm=np.array([0.0, 0, 1, 0, 0, 0]))
        assert _values(sa) == _values(sb)
        assert bool(sb.warning & 0x0001) == (i < 30)
        if i not in (40, 41):  # the set-point in use is the pose given (again after the switch)
            assert sb.cmd_cart_pose_m.tobytes() == pose.tobytes()
    with pytest.raises(Exception, match="cart_stiffness"):
        b.step(ArmCommand(cart_stiffness_npm_nmprad=np.array([np.nan] * 6)))


def test_krc_limit_check_equals_numpy() -> None:
    lim = np.radians([160.0, 110.0, 160.0, 110.0, 160.0, 110.0, 160.0])
    gen = np.random.default_rng(9)
    for q in gen.uniform(-1.01, 1.01, (500, 7)) * lim:
        hit = np.abs(q) >= lim
        assert software_limit_error(q, lim) == int(np.sum(1 << np.flatnonzero(hit)))
    assert software_limit_error(lim.copy(), lim) == 0x7F  # at the limit counts


def test_lockstep_reports_clipped_gains_every_cycle() -> None:
    robot = SimRobot(SimWorld(load_scene(PAPER), seed=1), start_cycles=0)
    robot.connect()
    pose = robot.measurement.msr_cart_pos.copy()
    cmd = CartesianCommand(pose_m=pose, stiffness_npm_nmprad=np.array([9000.0, 0, 0, 0, 0, 0]),
                           damping_ratio=np.full(6, 0.7), wrench_n_nm=np.zeros(6))
    statuses = []
    for n, _ in enumerate(robot.measurements()):
        if n == 3:
            cmd.stiffness_npm_nmprad[0] = 100.0
        if n == 6:
            break
        applied = robot.send(cmd)
        statuses.append(bool(applied.status & ApplyStatus.CLIPPED))
        if applied.status & ApplyStatus.CLIPPED:
            assert applied.command.stiffness_npm_nmprad[0] == 5000.0
    assert statuses == [True, True, True, False, False, False]


def test_placement_at_mouth_equals_placement() -> None:
    gen = np.random.default_rng(12)
    for _ in range(300):
        tcp, mouth = np.eye(4), np.eye(4)
        for p in (tcp, mouth):
            q, _r = np.linalg.qr(gen.normal(size=(3, 3)))
            p[:3, :3] = q
            p[:3, 3] = gen.normal(0.0, 0.5, 3)
        mat9 = mouth[:3, :3].copy().ravel()
        assert placement_at_mouth(tcp, mouth[:3, 3].copy(), mat9) == placement(tcp, mouth)


def test_divergence_seen_through_the_kept_warning_view() -> None:
    w = SimWorld(load_scene(PAPER), seed=1)
    w.step()
    w.data.qvel[0] = np.nan
    with pytest.raises(SimulationError, match="qvel"):
        w.advance()


def _samples_of(w: SimWorld, cmds: list[ArmCommand | None]) -> list[bytes]:
    out = []
    for i, cmd in enumerate(cmds):
        if i == 40:  # a physics step outside advance: the history ring starts elsewhere
            mujoco.mj_step(w.model, w.data)
        w.advance(cmd)
        s = w.ft_samples()
        out.append(s.wrench.tobytes() + s.time_ns.tobytes() + s.seq.tobytes()
                   + s.status.tobytes() + w.data.qpos.tobytes())
    return out


@pytest.mark.parametrize("overrides", [[], ["ft_sensor.rate=500"]])
def test_sensor_history_equals_per_step_readings(overrides: list[str]) -> None:
    # MuJoCo's sensor history (one mj_step call per cycle) against a copy of the
    # sensor after each physics step, pressing into the funnel and saturating
    scene = load_scene(PAPER, overrides)
    kept, per_step = SimWorld(scene, seed=3), SimWorld(scene, seed=3)
    assert kept._ft_steps.uses_history
    per_step._ft_steps._hist = None  # the per-step path
    pose = kept.last_state.tcp_pose_m.copy()
    pose[:3, 3] += 0.06 * pose[:3, 2]
    push = ArmCommand(cart_pose_m=pose, tcp_wrench_n_nm=np.array([0.0, 0.0, 400.0, 0, 0, 0]))
    cmds: list[ArmCommand | None] = [push] + [None] * 99
    assert _samples_of(kept, cmds) == _samples_of(per_step, cmds)


def test_sample_times_and_numbers_continue_across_blocks_and_jumps() -> None:
    model = FtSensorModel(FtSensorSettings(rate=1000.0), np.random.default_rng(1), np.zeros(3))
    rng = np.random.default_rng(2)
    t0, seq = 7, 0
    for k in range(600):
        n = int(rng.integers(0, 12)) if k % 50 == 0 else 5
        if k % 97 == 0:
            t0 += 1_234  # a jump: not where the last block ended
        s = model.process(np.zeros((n, 6)), t0)
        assert s.time_ns.tolist() == [t0 + 1_000_000 * i for i in range(n)]
        assert s.seq.tolist() == list(range(seq, seq + n))
        assert not (s.time_ns.flags.writeable or s.seq.flags.writeable)
        t0 += 1_000_000 * n
        seq += n
