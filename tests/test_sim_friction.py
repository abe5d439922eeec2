"""Joint friction (drivers/world/friction.py): a Stribeck curve on MuJoCo's dry friction.

A single hinge carrying the model, its level updated once per 5 ms cycle as
the simulated KRC does: a torque ramp breaks it away at the static level,
and a constant torque above the Coulomb level settles at the speed where
the closed-form curve equals the applied torque.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from scipy.optimize import brentq

from drivers.description.scene import ArmSettings, Scene
from drivers.world.friction import JointFriction

DT = 0.001
SUBSTEPS = 5


def _hinge(friction: JointFriction) -> tuple[mujoco.MjModel, mujoco.MjData]:
    xml = f"""<mujoco><option timestep="{DT}" gravity="0 0 0" integrator="implicitfast"/>
<worldbody><body><joint name="j" type="hinge" axis="0 0 1"
  solreffriction="0.002 1" solimpfriction="0.99 0.999 0.001"/>
<inertial pos="0 0 0" mass="1" diaginertia="0.02 0.02 0.02"/></body></worldbody>
<actuator><motor joint="j"/></actuator></mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    friction.install(m)
    return m, mujoco.MjData(m)


def _one(static: float, coulomb: float, viscous: float, vs: float) -> JointFriction:
    return JointFriction(np.array([static]), np.array([coulomb]), np.array([viscous]),
                         np.array([vs]))


def test_curve_closed_form() -> None:
    f = _one(1.3, 1.0, 0.5, 0.02)
    assert f.torque_nm(np.array([0.0]))[0] == pytest.approx(1.3)
    assert f.torque_nm(np.array([0.02]))[0] == pytest.approx(1.0 + 0.3 * np.exp(-1) + 0.01)
    assert f.torque_nm(np.array([1.0]))[0] == pytest.approx(1.0 + 0.5, rel=1e-9)
    v = np.linspace(0.0, 0.2, 2001)
    dry = f.dry_level_nm(v)
    assert np.all(np.diff(dry) <= 1e-15)  # falls monotonically from static to Coulomb
    assert np.max(np.abs(np.diff(dry))) < 0.01  # and continuously (no step)


def test_breakaway_at_the_static_level_then_sliding_at_the_curve() -> None:
    f = _one(static=0.40, coulomb=0.25, viscous=0.5, vs=0.05)
    m, d = _hinge(f)
    ramp_nm_per_s = 0.2
    broke_at = None
    for cycle in range(4000):
        f.apply(m, d.qvel)
        d.ctrl[0] = ramp_nm_per_s * cycle * SUBSTEPS * DT
        mujoco.mj_step(m, d, SUBSTEPS)
        if broke_at is None and abs(d.qvel[0]) > 0.01:
            broke_at = float(d.ctrl[0])
            break
    assert broke_at is not None
    # breaks away at the static level (not the Coulomb one), within the ramp's step
    assert broke_at == pytest.approx(0.40, abs=0.02)

    applied = 0.35  # above Coulomb + a little: steady speed where tau_f(v) = applied
    m, d = _hinge(f)
    d.qvel[0] = 0.5  # already sliding
    for _ in range(3000):
        f.apply(m, d.qvel)
        d.ctrl[0] = applied
        mujoco.mj_step(m, d, SUBSTEPS)
    # the stable root: on the rising branch, beyond the curve's minimum
    grid = np.linspace(0.0, 2.0, 20001)
    v_min = float(grid[np.argmin(f.torque_nm(grid))])
    expected = brentq(lambda v: f.torque_nm(np.array([v]))[0] - applied, v_min, 10.0)
    assert d.qvel[0] == pytest.approx(expected, rel=0.03)


def test_scene_builds_the_lwr_model_from_jubien_and_its_scale() -> None:
    arm = ArmSettings(friction_scale=0.01, static_ratio=1.5, stribeck_speed=0.03)
    f = JointFriction.of_arm(arm)
    assert np.allclose(f.coulomb_nm, 0.01 * np.array([11.9, 11.5, 8.98, 8.35, 8.31, 4.72, 6.04]))
    assert np.allclose(f.static_nm, 1.5 * f.coulomb_nm)
    assert np.allclose(f.viscous_nmsprad, 0.01 * np.array([14.4, 15.3, 6.55, 11.0, 4.29, 2.26,
                                                           1.6]))
    assert np.allclose(f.stribeck_radps, 0.03)


# -- the torque loop's factor r: link-side friction along TCF Y at the start pose -------
# Case II's KRC stiffness: TCF X, rot-Y and rot-Z held, Y, Z and rot-X free (paper.toml).
HELD, FREE = [0, 4, 5], [1, 2, 3]


def _hand_damping_y(jac: np.ndarray, viscous: np.ndarray) -> float:
    """Steady push along Y, nothing along Z and rot-X, the held axes not moving: the joint
    speeds ``D^-1 J^T w`` with ``w`` the push plus the held axes' reactions. The free
    axes' mobility is the Schur complement of ``A = J D^-1 J^T`` over the held ones."""
    a = jac @ np.diag(1.0 / viscous) @ jac.T
    s = a[np.ix_(FREE, FREE)] - a[np.ix_(FREE, HELD)] @ np.linalg.solve(
        a[np.ix_(HELD, HELD)], a[np.ix_(HELD, FREE)])
    return float(1.0 / s[0, 0])


def _hand_breakaway_y(jac: np.ndarray, coulomb: np.ndarray) -> float:
    """The least push along Y that slides: by virtual power, the least dry dissipation
    ``sum c_i |q'_i|`` over joint speeds that move Y at unit speed with the held axes
    still (a linear programme in q' = q+ - q-)."""
    from scipy.optimize import linprog

    n = jac.shape[1]
    a_eq = np.vstack([np.hstack([jac[HELD], -jac[HELD]]), np.hstack([jac[[1]], -jac[[1]]])])
    b_eq = np.r_[np.zeros(len(HELD)), 1.0]
    res = linprog(np.r_[coulomb, coulomb], A_eq=a_eq, b_eq=b_eq, bounds=[(0, None)] * (2 * n))
    assert res.success
    return float(res.fun)


def _push_y(scene: object, force_n: float, cycles: int) -> np.ndarray:
    """The TCP's travel along the start TCF's Y, per cycle, under a constant TCF Y force."""
    from drivers.world.arm import ArmCommand, ArmMode
    from drivers.world.world import SimWorld

    world = SimWorld(scene, seed=1)  # type: ignore[arg-type]
    start = world.tcp_pose.copy()
    world.step(ArmCommand(
        mode=ArmMode.CART_IMPEDANCE, cart_pose_m=start,
        cart_stiffness_npm_nmprad=np.array([5000.0, 0, 0, 0, 300.0, 300.0]),
        cart_damping_ratio=np.array([0.7, 0, 0, 0, 0.7, 0.7]),
        tcp_wrench_n_nm=np.array([0.0, force_n, 0, 0, 0, 0])))
    y = []
    for _ in range(cycles):
        world.step(None)
        y.append(float((start[:3, :3].T @ (world.tcp_pose[:3, 3] - start[:3, 3]))[1]))
    return np.array(y)


def _with_arm(paper_scene: Scene, **update: object) -> tuple[Scene, np.ndarray]:
    from drivers.world.world import SimWorld

    scene = paper_scene.model_copy(update={"arm": paper_scene.arm.model_copy(update=update)})
    return scene, SimWorld(scene, seed=1).jacobian


def test_link_side_damping_along_tcf_y_is_the_hand_calculation(paper_scene: Scene) -> None:
    """Viscous friction only (r = 1: Jubien's drive-side values at the link): a constant
    0.3 N along Y settles at the speed the joint values give by hand."""
    scene, jac = _with_arm(paper_scene, torque_loop_r=1.0, coulomb=(0.0,) * 7)
    b_y = _hand_damping_y(jac, np.asarray(scene.arm.viscous_friction()))
    y = _push_y(scene, 0.3, 300)
    speed = (y[-1] - y[-51]) / (50 * scene.fri.cycle)
    assert 0.3 / speed == pytest.approx(b_y, rel=0.08)


@pytest.mark.parametrize(("fraction", "slides"), [(0.9, False), (1.1, True)])
def test_breakaway_along_tcf_y_is_the_hand_calculation(
    paper_scene: Scene, fraction: float, slides: bool
) -> None:
    """Coulomb friction at r = 0.05 (static = Coulomb): 10 % below the hand breakaway the
    tool stays (the friction constraint's creep only), 10 % above it slides."""
    scene, jac = _with_arm(paper_scene, torque_loop_r=0.05, static_ratio=1.0)
    f_break = _hand_breakaway_y(jac, np.asarray(scene.arm.coulomb_friction()))
    y = _push_y(scene, fraction * f_break, 300)
    moved_last_s = abs(y[-1] - y[-201])
    assert bool(moved_last_s > 0.01) is slides
    assert slides or moved_last_s < 2e-4


def test_the_torque_loop_factor_scales_drive_friction_and_rotor_inertia_alike() -> None:
    """With r: the link side (FloBaRoID's, after the torque sensors) plus r times Jubien's
    drive side, per joint; the rotor inertia r times Jubien's."""
    link_c = np.array([0.611, 0.363, 0.304, 0.473, 0.595, 0.160, 0.038])
    link_v = np.array([1.069, 0.958, 0.223, 0.689, 0.065, 0.252, 0.076])
    arm = ArmSettings(torque_loop_r=0.1, friction_scale=0.5, armature_scale=0.3)
    assert np.allclose(arm.coulomb_friction(),
                       link_c + 0.1 * np.array([11.9, 11.5, 8.98, 8.35, 8.31, 4.72, 6.04]))
    assert np.allclose(arm.viscous_friction(),
                       link_v + 0.1 * np.array([14.4, 15.3, 6.55, 11.0, 4.29, 2.26, 1.6]))
    assert arm.rotor_fraction() == 0.1
    own = ArmSettings(torque_loop_r=0.0, link_coulomb=(0.0,) * 7)
    assert np.allclose(own.coulomb_friction(), 0.0)  # a scene's own link side
    assert ArmSettings(armature_scale=0.3).rotor_fraction() == 0.3  # r unset: the old keys
