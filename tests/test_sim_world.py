"""SimWorld against physics and closed forms (issue 3 acceptance tests)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path

import mujoco
import numpy as np
import pytest

import ffexp.errors
from drivers.base.impedance import cart_impedance_torque, cartesian_mobility, normalized_damping
from drivers.base.placement import Placement
from drivers.base.types import FtStatus
from drivers.description.scene import Scene
from drivers.errors import InvalidCommandError, SimulationError
from drivers.world.arm import ArmCommand, ArmMode, ArmState, ArmWarning
from drivers.world.friction import JointFriction
from drivers.world.world import SimWorld
from ffexp.scenarios.funnel import truth_placement

_N_ARM = 7

G = 9.81
STIFF = np.array([5000.0, 5000.0, 5000.0, 300.0, 300.0, 300.0])


#: The world's mechanics are tested on a free target (no air hose) unless a test
#: gives the hose: the closed forms below are those of a body on the bed alone.
NO_HOSE = {"stiffness": 0.0, "damping": 0.0}


def scene(**sections: Mapping[str, object]) -> Scene:
    data: dict[str, object] = dict(sections)
    target = dict(sections.get("target", {}))
    target["hose"] = {**NO_HOSE, **dict(target.get("hose", {}))}  # type: ignore[arg-type]
    data["target"] = target
    return Scene.model_validate(data)


def far_target() -> dict[str, object]:
    """Target out of the tool's reach."""
    return {"distance": 0.3}


def push(fz: float = 0.0, fy: float = 0.0, fx: float = 0.0) -> ArmCommand:
    return ArmCommand(tcp_wrench_n_nm=np.array([fx, fy, fz, 0.0, 0.0, 0.0]))


def test_cartesian_inertia_predicts_free_acceleration() -> None:
    """K = 0 on Y, F_cmd on Y: the TCP accelerates as (J M^-1 J^T) F predicts."""
    w = SimWorld(scene(arm={"friction_scale": 0.0}, target=far_target()))
    m0 = w.last_state
    mob = cartesian_mobility(m0.jacobian, m0.mass_matrix)
    force = 4.0
    a_pred = mob[1, 1] * force
    p0 = m0.tcp_pose_m[:3, 3].copy()
    y_axis = m0.tcp_pose_m[:3, 1].copy()
    ts, ys = [], []
    for _ in range(6):  # 30 ms
        m = w.step(push(fy=force))
        ts.append(w.time)
        ys.append(float(y_axis @ (m.tcp_pose_m[:3, 3] - p0)))
    a_fit = 2.0 * np.polyfit(ts, ys, 2)[0]
    assert a_fit == pytest.approx(a_pred, rel=0.05)
    # The Cartesian inertia itself: Lambda = (J M^-1 J^T)^-1, Lambda_yy of a few kg.
    lam = np.linalg.inv(mob)
    assert 1.0 < lam[1, 1] < 15.0


def test_stiff_axis_deflects_by_f_over_k() -> None:
    """X held at K = 5000 N/m (paper: maximal) deflects F/K under F_cmd on X."""
    w = SimWorld(scene(target=far_target()))
    p0 = w.last_state.tcp_pose_m[:3, 3].copy()
    x_axis = w.last_state.tcp_pose_m[:3, 0].copy()
    force = 25.0
    for _ in range(400):  # 2 s
        m = w.step(push(fx=force))
    dx = float(x_axis @ (m.tcp_pose_m[:3, 3] - p0))
    assert dx == pytest.approx(force / 5000.0, rel=0.05)


def test_actuators_realise_the_krc_law() -> None:
    """MuJoCo's actuator torques equal tau = J^T (K e - D xdot + F) + g at an offset pose."""
    w = SimWorld(scene(target=far_target()))
    m0 = w.last_state
    cmd_pose = m0.tcp_pose_m.copy()
    cmd_pose[:3, 3] += cmd_pose[:3, :3] @ np.array([0.004, -0.003, 0.005])
    c, s = math.cos(0.01), math.sin(0.01)
    cmd_pose[:3, :3] = cmd_pose[:3, :3] @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    k = STIFF.copy()
    d = np.full(6, 0.7)
    f_cmd = np.array([1.0, -2.0, 3.0, 0.1, -0.2, 0.05])
    w._take(
        ArmCommand(
            cart_pose_m=cmd_pose, cart_stiffness_npm_nmprad=k, cart_damping_ratio=d,
            tcp_wrench_n_nm=f_cmd,
        )
    )
    w._apply()
    mujoco.mj_forward(w.model, w.data)
    tau_sim = w.data.qfrc_actuator[:7].copy()
    damp = normalized_damping(k, d, np.diag(w.cart_inertia))
    tau_ref = cart_impedance_torque(
        m0.jacobian, cmd_pose, m0.tcp_pose_m, np.zeros(6), k, damp, f_cmd, m0.gravity_nm
    )
    np.testing.assert_allclose(tau_sim, tau_ref, rtol=0.01, atol=0.01)


@pytest.mark.slow
def test_holds_commanded_pose_for_60_s() -> None:
    """Stiff impedance, cmd = current pose, no F_cmd: drift < 1 mm over 60 s."""
    w = SimWorld(scene(target=far_target()))
    p0 = w.last_state.tcp_pose_m[:3, 3].copy()
    cmd = ArmCommand(
        cart_pose_m=w.last_state.tcp_pose_m.copy(),
        cart_stiffness_npm_nmprad=STIFF, cart_damping_ratio=np.full(6, 0.7),
    )
    worst = 0.0
    for i in range(12000):
        m = w.step(cmd if i == 0 else None)
        worst = max(worst, float(np.linalg.norm(m.tcp_pose_m[:3, 3] - p0)))
    assert worst < 1e-3


def _target_decel(mu: float, seconds: float) -> tuple[float, list[float]]:
    w = SimWorld(scene(target={"mu": mu, "distance": 0.3, "velocity": (0.1, 0.0, 0.0)}))
    ts, vs = [], []
    for _ in range(round(seconds / 0.005)):
        m = w.step()
        assert m.truth is not None
        ts.append(w.time)
        vs.append(float(m.truth.bodies["target"].twist[0]))
    return -float(np.polyfit(ts, vs, 1)[0]), vs


@pytest.mark.parametrize(("mu", "seconds"), [(0.005, 1.5), (0.02, 0.4)])
def test_target_decelerates_at_mu_g(mu: float, seconds: float) -> None:
    decel, vs = _target_decel(mu, seconds)
    assert decel == pytest.approx(mu * G, rel=0.05)
    assert vs[-1] > 0.0  # still sliding within the fit window


def test_frictionless_target_keeps_momentum() -> None:
    w = SimWorld(scene(target={"mu": 0.0, "distance": 0.3, "velocity": (0.1, 0.0, 0.0)}))
    for _ in range(400):  # 2 s
        m = w.step()
    assert m.truth is not None
    assert m.truth.bodies["target"].twist[0] == pytest.approx(0.1, rel=0.01)
    moved = m.truth.bodies["target"].pose[0, 3] - w.layout.target_pos[0]
    assert moved == pytest.approx(0.2, rel=0.01)


def test_bed_friction_is_isotropic() -> None:
    """Diagonal slide: speed drops at mu g and the direction does not turn."""
    v0 = 0.1 / math.sqrt(2.0)
    w = SimWorld(scene(target={"mu": 0.01, "distance": 0.3, "velocity": (v0, v0, 0.0)}))
    for _ in range(100):  # 0.5 s
        m = w.step()
    assert m.truth is not None
    vx, vy = m.truth.bodies["target"].twist[:2]
    assert math.hypot(vx, vy) == pytest.approx(0.1 - 0.01 * G * 0.5, rel=0.02)
    assert vx == pytest.approx(vy, rel=1e-3)


#: The world's mechanics are tested at 1 % of Jubien's friction (the scene
#: default before the paper calibration moved to 0.1 %, see data/scenes/paper.toml).
ARM_1PCT = {"friction_scale": 0.01}


def test_joint_friction_breakaway_matches_closed_form() -> None:
    """The tool stays put while every |J^T F|_i is below joint i's static (breakaway) friction."""
    w0 = SimWorld(scene(arm=ARM_1PCT, target=far_target()))
    m0 = w0.last_state
    static = JointFriction.of_arm(w0.scene.arm).static_nm
    e_y = np.array([0.0, 1.0, 0.0, 0.0, 0.0, 0.0])
    breakaway = 1.0 / float(np.max(np.abs(m0.jacobian.T @ e_y) / static))

    def moved(force: float) -> float:
        w = SimWorld(scene(arm=ARM_1PCT, target=far_target()))
        p0 = w.last_state.tcp_pose_m[:3, 3].copy()
        for _ in range(100):  # 0.5 s
            m = w.step(push(fy=force))
        return float(np.linalg.norm(m.tcp_pose_m[:3, 3] - p0))

    assert moved(0.8 * breakaway) < 2e-4
    assert moved(1.5 * breakaway) > 2e-3


def _paper_push(
    force: float, seconds: float, cycle: float = 0.005
) -> tuple[SimWorld, list[ArmState]]:
    w = SimWorld(scene(fri={"cycle": cycle}, arm=ARM_1PCT))
    out = []
    cmd = push(fz=force)
    for _ in range(round(seconds / cycle)):
        out.append(w.step(cmd))
    return w, out


def _placement(m: ArmState) -> Placement:
    """The tool tip in the funnel by the state's truth (the funnel scenario's measure)."""
    assert m.truth is not None
    p = truth_placement(m.truth, m.tcp_pose_m)
    assert p is not None
    return p


@pytest.fixture(scope="module")
def paper_push() -> tuple[SimWorld, list[ArmState]]:
    # 2 N: above the ~1 N below which the funnels stick (paper), below the force
    # that throws the target out of the arm's reach before it is seated
    return _paper_push(2.0, 5.0)


@pytest.mark.slow
def test_push_slides_funnels_into_alignment(paper_push: tuple[SimWorld, list[ArmState]]) -> None:
    w, ms = paper_push
    placed = [_placement(m) for m in ms]
    first, last = placed[0], placed[-1]
    assert abs(first.lateral) > 0.01 and abs(first.yaw) > math.radians(7)
    assert any(m.truth is not None and m.truth.in_contact for m in ms)
    assert abs(last.lateral) < 2e-3
    assert abs(last.yaw) < math.radians(2.5)
    assert last.insertion > w.layout.funnel_seat_depth - 0.005
    # seated (within the funnels' play, 2.5 mm and 3 deg), and it stays seated for the last
    # second
    assert all(abs(p.lateral) <= 2.5e-3 and abs(p.yaw) <= math.radians(3.0)
               and p.insertion >= w.layout.funnel_seat_depth - 0.005 for p in placed[-200:])


@pytest.mark.slow
def test_target_moves_away_by_the_contact_impulse() -> None:
    """Over the final stretch of unbroken contact, the target's momentum change equals
    the contact impulse on it minus bed friction. FRI cycle = physics step here, so
    the truth samples every step's contact force (the impulse sum is exact)."""
    w, ms = _paper_push(2.0, 3.5, cycle=0.001)
    dt = w.scene.fri.cycle
    mass, mu = w.scene.target.mass, w.scene.target.mu
    start = len(ms)
    while start > 0 and ms[start - 1].truth is not None and ms[start - 1].truth.in_contact:
        start -= 1
    window = ms[start:]
    assert len(window) * dt > 1.0  # at least 1 s of continuous contact
    p = np.zeros(2)
    for m in window[1:]:
        assert m.truth is not None
        f_on_tool_world = m.tcp_pose_m[:3, :3] @ m.truth.contact_wrench[:3]
        p -= f_on_tool_world[:2] * dt
        v = m.truth.bodies["target"].twist[:2]
        speed = float(np.linalg.norm(v))
        if speed > 1e-4:
            p -= mu * mass * G * v / speed * dt
    v0 = window[0].truth.bodies["target"].twist[:2]
    v1 = window[-1].truth.bodies["target"].twist[:2]
    # it was pushed away along the approach direction (TCF +Z = world +x) ...
    moved = ms[-1].truth.bodies["target"].pose[:2, 3] - ms[0].truth.bodies["target"].pose[:2, 3]
    assert moved[0] > 0.03 and abs(moved[1]) < moved[0]
    # ... and its momentum change is the impulse it received
    dp = mass * (v1 - v0)
    scale = float(np.abs(p).max())
    np.testing.assert_allclose(dp, p, atol=0.05 * scale + 0.002)


@pytest.mark.slow
def test_sensor_reads_our_sign_in_contact(paper_push: tuple[SimWorld, list[ArmState]]) -> None:
    """Pushing +Z into the target, the true contact wrench and the sensor read w[2] < 0."""
    _, ms = paper_push
    contact = [m for m in ms if m.truth is not None and m.truth.contact_wrench[2] < -0.5]
    assert contact
    assert all(m.ext_wrench_n_nm[2] < 0.0 for m in contact)


def test_sensor_matches_contact_wrench_during_push() -> None:
    """Sensor minus its free-motion reading equals the true contact wrench.

    The true wrench and the cycle's last F/T sample refer to the same physics
    step. Before contact the reading holds bias, drift and the tool load; the
    tool's inertia (0.25 kg) adds ``-m a`` during impacts, hence 3 %. (The sensor's
    path delay is off: a sample then carries its own step's wrench.)
    """
    w = SimWorld(scene(ft_sensor={"delay_s": 0.0}))
    cmd = push(fz=3.0)
    free: list[float] = []
    pairs: list[tuple[float, float]] = []
    for _ in range(800):
        m = w.step(cmd)
        ft = w.ft_samples()
        assert m.truth is not None
        if not m.truth.in_contact and not pairs:
            free.append(float(ft.wrench[:, 2].mean()))
        elif m.truth.contact_wrench[2] < -0.3:
            pairs.append((float(ft.wrench[-1, 2]), float(m.truth.contact_wrench[2])))
    assert len(pairs) >= 50
    base = float(np.mean(free[-40:]))
    for reading, truth in pairs:
        assert reading - base < 0.0
        assert reading - base == pytest.approx(truth, abs=0.2 + 0.03 * abs(truth))


def test_static_reading_shows_noise_and_quantisation() -> None:
    w = SimWorld(scene(target=far_target()))
    for _ in range(200):
        w.step()
    s = w.ft_samples()
    assert len(s) == 1000
    fz = s.wrench[:, 2]
    assert np.std(fz) > 0.01  # noise visible
    np.testing.assert_allclose(fz * 16.0, np.rint(fz * 16.0), atol=1e-9)  # 1/16 N counts
    assert np.all(s.status == 0)
    # The static reading carries the tool's weight on -X (gravity along -X of TCF).
    m_tool = w.scene.tool.mass
    bias_x = w.ft_model.bias[0] + w.ft_model.drift[0]
    assert np.mean(s.wrench[:, 0]) - bias_x == pytest.approx(-m_tool * G, abs=0.05)


def test_saturation_flagged_in_world() -> None:
    """With a 1 N range on X the tool's own weight saturates the gauge."""
    w = SimWorld(scene(target=far_target(),
                       ft_sensor={"range": (1.0, 145.0, 290.0, 5.0, 5.0, 5.0),
                                  "bias_std": (0.0, 0.0)}))
    w.step()
    s = w.ft_samples()
    assert np.all(s.status & FtStatus.SATURATION)
    assert np.all(np.abs(s.wrench[:, 0]) <= 1.0 + 1 / 32)


def test_same_seed_identical_runs() -> None:
    def run(seed: int) -> tuple[list[ArmState], np.ndarray]:
        w = SimWorld(scene(), seed=seed)
        ms, ft = [], []
        for i in range(150):
            ms.append(w.step(push(fz=3.0, fy=0.3 * math.sin(i / 10))))
            ft.append(w.ft_samples().wrench)
        return ms, np.concatenate(ft)

    a, fa = run(5)
    b, fb = run(5)
    _, fc = run(6)
    assert np.array_equal(fa, fb)
    assert not np.array_equal(fa, fc)
    for ma, mb in zip(a, b, strict=True):
        for name in ("jnt_pos_rad", "tcp_pose_m", "jnt_trq_nm", "ext_wrench_n_nm", "jacobian"):
            assert np.array_equal(getattr(ma, name), getattr(mb, name)), name


def test_state_fields_are_consistent() -> None:
    w = SimWorld(scene(target=far_target()))
    m = w.step()
    assert m.cycle == 1 and m.time_ns == 5_000_000
    assert m.mode == ArmMode.CART_IMPEDANCE
    assert m.jacobian.shape == (6, 7) and m.mass_matrix.shape == (7, 7)
    np.testing.assert_allclose(m.mass_matrix, m.mass_matrix.T, atol=1e-12)
    assert np.all(np.linalg.eigvalsh(m.mass_matrix) > 0)
    # Held still with gravity compensated: measured torque = gravity torque.
    np.testing.assert_allclose(m.jnt_trq_nm, m.gravity_nm, atol=0.05)
    np.testing.assert_allclose(m.ext_jnt_trq_nm, 0.0, atol=1e-9)
    # TCF: X up (gravity along -X), Z horizontal.
    np.testing.assert_allclose(m.tcp_pose_m[:3, 0], [0.0, 0.0, 1.0], atol=1e-4)
    assert abs(m.tcp_pose_m[2, 2]) < 1e-4
    np.testing.assert_allclose(m.cmd_cart_pose_m, w.tcp_pose, atol=1e-3)


def test_joint_position_mode_tracks() -> None:
    w = SimWorld(scene(target=far_target()))
    q0 = w.last_state.jnt_pos_rad.copy()
    q_cmd = q0 + np.array([0.05, -0.03, 0.0, 0.04, 0.0, 0.0, 0.02])
    cmd = ArmCommand(mode=ArmMode.JOINT_POSITION, jnt_pos_rad=q_cmd)
    for _ in range(200):
        m = w.step(cmd)
    assert m.mode == ArmMode.JOINT_POSITION
    np.testing.assert_allclose(m.jnt_pos_rad, q_cmd, atol=2e-3)


def test_torque_limits_clamp_and_warn() -> None:
    w = SimWorld(scene(target=far_target()))
    cmd = ArmCommand(jnt_trq_nm=np.array([0, 0, 0, 0, 0, 0, 500.0]))
    m = w.step(cmd)
    assert abs(w.data.qfrc_actuator[6]) <= 38.0 + 1e-9
    assert m.warning & ArmWarning.TORQUE_LIMIT


def test_stiffness_clipped_to_max_with_warning() -> None:
    w = SimWorld(scene(target=far_target()))
    cmd = ArmCommand(cart_stiffness_npm_nmprad=np.array([9e3, 0, 0, 0, 500.0, 0]))
    m = w.step(cmd)
    assert m.warning & ArmWarning.STIFFNESS_CLIPPED
    assert -w.model.actuator_biasprm[7, 1] == pytest.approx(5000.0)
    assert -w.model.actuator_biasprm[11, 1] == pytest.approx(300.0)


def test_non_finite_command_rejected() -> None:
    w = SimWorld(scene(target=far_target()))
    with pytest.raises(InvalidCommandError):
        w.step(push(fz=float("nan")))


def test_hose_drag_decays_exponentially() -> None:
    """Hose drag b on a frictionless target: v(t) = v0 exp(-b t / m)."""
    b = 6.0
    w = SimWorld(scene(target={"mu": 0.0, "distance": 0.3, "velocity": (0.1, 0.0, 0.0),
                               "hose": {"damping": b}}))
    for _ in range(200):  # 1 s
        m = w.step()
    assert m.truth is not None
    v = m.truth.bodies["target"].twist[0]
    assert v == pytest.approx(0.1 * math.exp(-b * 1.0 / 12.0), rel=0.01)


def test_hose_spring_oscillates_at_its_natural_frequency() -> None:
    """Hose spring k on a frictionless target: x(t) = (v0 / w) sin(w t), w = sqrt(k / m)."""
    k = 12.0
    omega = math.sqrt(k / 12.0)
    w = SimWorld(scene(target={"mu": 0.0, "distance": 0.3, "velocity": (0.05, 0.0, 0.0),
                               "hose": {"stiffness": k}}))
    x0 = w.last_state.truth.bodies["target"].pose[0, 3]
    for _ in range(200):  # 1 s
        m = w.step()
    assert m.truth is not None
    x = m.truth.bodies["target"].pose[0, 3] - x0
    assert x == pytest.approx(0.05 / omega * math.sin(omega * 1.0), rel=0.01)


def test_joint_impedance_deflects_by_tau_over_k() -> None:
    """Joint impedance on A1 with addJntTrq: static deflection tau / k (no joint friction)."""
    w = SimWorld(scene(arm={"friction_scale": 0.0}, target=far_target()))
    q0 = w.last_state.jnt_pos_rad.copy()
    k = np.full(7, 800.0)
    tau = np.array([8.0, 0, 0, 0, 0, 0, 0])
    cmd = ArmCommand(
        mode=ArmMode.JOINT_IMPEDANCE, jnt_pos_rad=q0, jnt_stiffness_nmprad=k,
        jnt_damping_ratio=np.full(7, 0.7), jnt_trq_nm=tau,
    )
    for _ in range(300):
        m = w.step(cmd)
    assert m.mode == ArmMode.JOINT_IMPEDANCE
    assert m.jnt_pos_rad[0] - q0[0] == pytest.approx(8.0 / 800.0, rel=0.02)


def test_divergence_raises_instead_of_a_silent_reset(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A blown-up state raises SimulationError (MuJoCo would reset to t = 0 and log to a file)."""
    monkeypatch.chdir(tmp_path)
    w = SimWorld(scene(target=far_target()))
    for _ in range(3):
        w.step()
    t = w.data.time
    w.data.qvel[:_N_ARM] = 1e300
    end = f"{t + w.cycle_ns * 1e-9:.4f}".replace(".", r"\.")
    with pytest.raises(ffexp.errors.SimulationError,
                       match=rf"^physics diverged at t = {end} s: .*qvel") as info:
        w.step()
    assert isinstance(info.value, SimulationError)  # one class, re-exported by ffexp
    assert w.data.time > t  # not reset to 0
    assert list(tmp_path.iterdir()) == []  # no MUJOCO_LOG.TXT


def test_a_healthy_run_leaves_the_warning_counters_alone() -> None:
    w = SimWorld(scene(target=far_target()))
    for _ in range(20):
        w.step(push(fz=5.0))
    assert [w.data.warning[i].number for i in (
        mujoco.mjtWarning.mjWARN_BADQACC, mujoco.mjtWarning.mjWARN_BADQPOS,
        mujoco.mjtWarning.mjWARN_BADQVEL)] == [1, 1, 1]


def _contact_wrench_by_contact(w: SimWorld) -> np.ndarray:
    """Reference: mj_contactForce contact by contact, summed at the TCP, TCF."""
    m, d = w.model, w.data
    tcp = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "tcp")
    p, rot = d.site_xpos[tcp], d.site_xmat[tcp].reshape(3, 3)
    total = np.zeros(6)
    cf = np.zeros(6)
    for i in range(d.ncon):
        c = d.contact[i]
        tool = [m.geom_bodyid[g] == w._tool_body and m.geom_contype[g] != 0 for g in c.geom]
        if not any(tool) or c.efc_address < 0:
            continue
        mujoco.mj_contactForce(m, d, i, cf)
        f = cf[:3] @ c.frame.reshape(3, 3) * (-1.0 if tool[0] else 1.0)
        total[:3] += f
        total[3:] += np.cross(c.pos - p, f)
    return np.concatenate([rot.T @ total[:3], rot.T @ total[3:]])


def test_contact_wrench_equals_the_sum_over_contacts() -> None:
    """The vectorised contact wrench against mj_contactForce per contact, pressing in the funnel."""
    w = SimWorld(scene())
    pose = w.last_state.tcp_pose_m.copy()
    pose[:3, 3] += 0.045 * pose[:3, 2]
    cmd = ArmCommand(cart_pose_m=pose, tcp_wrench_n_nm=np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0]))
    pressing = 0
    for k in range(500):
        w.advance(cmd)
        if k % 50 == 49:
            mujoco.mj_forward(w.model, w.data)
            got, touching = w.contact_wrench()
            want = _contact_wrench_by_contact(w)
            np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)
            pressing += bool(touching and np.linalg.norm(want[:3]) > 0.1)
    assert pressing >= 3


def test_reused_cartesian_inertia_keeps_the_damping_within_0_1_percent() -> None:
    """The KRC damping's Cartesian inertia is reused while no joint moved 1 mrad."""
    from drivers.base.impedance import cartesian_inertia

    w = SimWorld(scene())
    pose = w.last_state.tcp_pose_m.copy()
    pose[:3, 3] += 0.045 * pose[:3, 2]
    cmd = ArmCommand(cart_pose_m=pose, tcp_wrench_n_nm=np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0]))
    reused = 0
    for _ in range(400):
        before = w.cart_inertia
        w.advance(cmd)
        reused += w.cart_inertia is before
        exact = np.diag(cartesian_inertia(w.jacobian, w.mass_matrix))
        ratio = np.sqrt(np.diag(w.cart_inertia) / exact)  # damping ~ sqrt(inertia)
        assert np.max(np.abs(ratio - 1.0)) < 1e-3
    assert 0 < reused < 400


def test_advance_without_reading_the_state_changes_nothing() -> None:
    """A world whose states are read every 7th cycle runs bit-identically to one read
    every cycle (the state is built lazily, the physics does not depend on it)."""
    a, b = SimWorld(scene(), seed=3), SimWorld(scene(), seed=3)
    pose = a.last_state.tcp_pose_m.copy()
    pose[:3, 3] += 0.045 * pose[:3, 2]
    cmd = ArmCommand(cart_pose_m=pose, tcp_wrench_n_nm=np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0]))
    for k in range(300):
        sa = a.step(cmd)
        b.advance(cmd)
        fa, fb = a.ft_samples(), b.ft_samples()
        np.testing.assert_array_equal(fa.wrench, fb.wrench)
        if k % 7 == 0:
            sb = b.last_state
            assert sb is b.last_state  # built once per cycle
            for name in ("jnt_pos_rad", "tcp_pose_m", "jnt_trq_nm", "ext_wrench_n_nm",
                         "jacobian", "mass_matrix"):
                np.testing.assert_array_equal(getattr(sa, name), getattr(sb, name))
            assert sa.truth.in_contact == sb.truth.in_contact
    assert a.last_state.truth.in_contact  # the comparison covered contact


def test_the_state_of_a_cycle_is_kept_when_the_target_is_pushed() -> None:
    """set_target_velocity after a cycle does not change that cycle's reported state."""
    w = SimWorld(scene(target=far_target()))
    w.advance()
    twist_before = SimWorld(scene(target=far_target()))
    twist_before.advance()
    w.set_target_velocity(0.1, 0.0, 0.0)
    np.testing.assert_array_equal(w.last_state.truth.bodies["target"].twist,
                                  twist_before.last_state.truth.bodies["target"].twist)
