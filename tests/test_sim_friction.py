"""Joint friction (drivers/sim/friction.py): a Stribeck curve on MuJoCo's dry friction.

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

from drivers.description.scene import ArmSettings
from drivers.sim.friction import JointFriction

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
