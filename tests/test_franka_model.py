"""The FR3's description and the driver's model of it, against closed forms and against
MuJoCo's own kinematics and dynamics of the same description (an independent computation),
and the driver's impedance law against the equation it implements."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from drivers.base.types import CartesianCommand
from drivers.description import load_scene
from drivers.description.fr3 import FR3, PAPER_SCENE_OVERRIDES
from drivers.franka.law import ImpedanceLaw
from drivers.franka.model import ArmModel

ROOT = Path(__file__).resolve().parents[1]


def test_the_zero_pose_flange_is_where_franka_publishes_it() -> None:
    # every joint at 0: the flange at x = a4 + a5 + a7, z = d1 + d3 + d5 - d_F, pointing down
    pose = FR3.flange_pose([0.0] * 7)
    assert pose[:3, 3] == pytest.approx([0.088, 0.0, 0.333 + 0.316 + 0.384 - 0.107], abs=1e-12)
    assert pose[:3, 2] == pytest.approx([0.0, 0.0, -1.0], abs=1e-12)


def test_the_scene_file_is_the_paper_scene_with_the_fr3_overrides() -> None:
    a = load_scene(ROOT / "data/scenes/paper.toml", PAPER_SCENE_OVERRIDES).model_dump()
    b = load_scene(ROOT / "data/scenes/paper-fr3.toml").model_dump()
    assert a == b


def _world():  # type: ignore[no-untyped-def]
    from drivers.world.world import SimWorld

    return SimWorld(load_scene(ROOT / "data/scenes/paper-fr3.toml"), seed=0)


def test_the_fr3_tcp_is_where_the_lwr4s_is() -> None:
    from drivers.world.world import SimWorld

    lwr = SimWorld(load_scene(ROOT / "data/scenes/paper.toml"), seed=0).tcp_pose
    assert np.abs(_world().tcp_pose - lwr).max() < 1e-4


def test_the_models_jacobian_and_pose_equal_mujocos() -> None:
    from drivers.franka.emulate.controller import flange_to_tcp

    w = _world()
    st = w.last_state
    jac, tcp = ArmModel().jacobian_tcf(st.jnt_pos_rad, flange_to_tcp(w))
    base = np.eye(4)
    base[:3, 3] = w.scene.arm.base_pos
    assert np.abs(base @ tcp - st.tcp_pose_m).max() < 1e-12
    assert np.abs(jac - st.jacobian).max() < 1e-12


def test_the_mass_matrix_is_symmetric_positive_and_holds_the_rotors() -> None:
    m = ArmModel().mass_matrix(np.array([0.1, -0.3, 0.2, -1.8, 0.1, 1.9, 0.5]))
    assert np.allclose(m, m.T)
    assert np.all(np.linalg.eigvalsh(m) > 0)
    # joint 7 turns only the last link about its own axis: its rotor and Izz
    assert m[6, 6] == pytest.approx(FR3.rotor_inertias_kgm2[6] + FR3.link_inertias_kgm2[6][2]
                                    + FR3.link_masses_kg[6] * np.hypot(*FR3.link_coms_m[6][:2])
                                    ** 2, rel=1e-9)


def _law(**kw: float) -> ImpedanceLaw:
    return ImpedanceLaw(ArmModel(), stiffness_max=(3000.0, 300.0), nullspace_damping=0.0,
                        torque_rate_nmps=1e9, **kw)


def test_at_the_set_point_at_rest_the_law_applies_only_the_wrench() -> None:
    q = np.array([0.0, -0.4, 0.0, -2.0, 0.0, 1.6, 0.7])
    tool = np.eye(4)
    jac, tcp = ArmModel().jacobian_tcf(q, tool)
    wrench = np.array([1.0, -2.0, 3.0, 0.1, 0.2, -0.3])
    cmd = CartesianCommand(pose_m=tcp, stiffness_npm_nmprad=np.full(6, 500.0),
                           damping_ratio=np.full(6, 0.7), wrench_n_nm=wrench)
    tau = _law().torque(q, np.zeros(7), tcp, tool, cmd)
    assert tau == pytest.approx(jac.T @ wrench, abs=1e-12)


def test_a_small_offset_gives_the_spring_and_motion_the_damping() -> None:
    q = np.array([0.0, -0.4, 0.0, -2.0, 0.0, 1.6, 0.7])
    tool = np.eye(4)
    model = ArmModel()
    jac, tcp = model.jacobian_tcf(q, tool)
    target = tcp.copy()
    target[:3, 3] += tcp[:3, :3] @ np.array([0.0, 0.0, 0.01])  # 1 cm along TCF z
    k = np.array([0.0, 0.0, 1000.0, 0.0, 0.0, 0.0])
    cmd = CartesianCommand(pose_m=target, stiffness_npm_nmprad=k,
                           damping_ratio=np.array([0, 0, 1.0, 0, 0, 0]), wrench_n_nm=np.zeros(6))
    assert _law().torque(q, np.zeros(7), tcp, tool, cmd) == pytest.approx(
        jac.T @ np.array([0, 0, 10.0, 0, 0, 0]), abs=1e-9)
    dq = np.linalg.pinv(jac) @ np.array([0, 0, 0.1, 0, 0, 0])  # 0.1 m/s along z
    lam = np.linalg.inv(jac @ np.linalg.solve(model.mass_matrix(q), jac.T))
    d_z = 2.0 * np.sqrt(1000.0 * lam[2, 2])
    cmd.pose_m = tcp
    tau = _law().torque(q, dq, tcp, tool, cmd)
    assert tau == pytest.approx(jac.T @ np.array([0, 0, -d_z * 0.1, 0, 0, 0]), abs=1e-9)


def test_the_torque_rate_and_the_joint_limits_bound_the_law() -> None:
    q = np.array([0.0, -0.4, 0.0, -2.0, 0.0, 1.6, 0.7])
    tool = np.eye(4)
    _jac, tcp = ArmModel().jacobian_tcf(q, tool)
    law = ImpedanceLaw(ArmModel(), stiffness_max=(3000.0, 300.0), nullspace_damping=0.0)
    law.reset()
    cmd = CartesianCommand(pose_m=tcp, stiffness_npm_nmprad=np.zeros(6),
                           damping_ratio=np.zeros(6), wrench_n_nm=np.array([0, 0, 500.0, 0, 0, 0]))
    first = law.torque(q, np.zeros(7), tcp, tool, cmd)
    assert np.max(np.abs(first)) == pytest.approx(1.0)  # 1000 N m/s for 1 ms from zero
    for _ in range(200):
        tau = law.torque(q, np.zeros(7), tcp, tool, cmd)
    assert np.all(np.abs(tau) <= np.array([87.0] * 4 + [12.0] * 3) + 1e-12)


def test_cross3_is_numpys_cross_bit_for_bit() -> None:
    """The plain-float cross product the model uses gives np.cross's values, signs of zero
    included, on random vectors of many scales, with zeros and ones among them."""
    from drivers.carrier.body import cross3

    rng = np.random.default_rng(11)
    special = np.array([0.0, -0.0, 1.0, -1.0, 1e-300, 1e300])
    for _ in range(3000):
        a = rng.normal(size=3) * 10.0 ** rng.integers(-8, 8, 3)
        b = rng.normal(size=3) * 10.0 ** rng.integers(-8, 8, 3)
        if rng.random() < 0.3:
            a[rng.integers(0, 3)] = rng.choice(special)
            b[rng.integers(0, 3)] = rng.choice(special)
        got = np.array(cross3(a, b))
        with np.errstate(over="ignore", invalid="ignore"):  # (1e300 squared: inf, as floats)
            ref = np.cross(a, b)
        assert got.tobytes() == ref.tobytes(), (a, b)
