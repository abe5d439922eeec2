"""The air hose that holds the target (scene ``target.hose``): a spring-damper in the bed plane.

Checked against the closed forms of a damped oscillator: a constant push moves
the target to F / k, and it rings at the damped frequency sqrt(k/m - (c/2m)^2)
with the decay rate c / 2m, where m is the target's whole moving mass.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from drivers.sim.scene import Scene
from drivers.sim.world import SimWorld

K_NPM = 200.0
C_NSPM = 20.0
PUSH_N = 0.8


def _world(mu: float = 0.0) -> SimWorld:
    scene = Scene.model_validate(
        {"target": {"mu": mu, "distance": 0.3, "hose": {"stiffness": K_NPM, "damping": C_NSPM}}})
    return SimWorld(scene)


def _moving_mass_kg(w: SimWorld) -> float:
    body = mujoco.mj_name2id(w.model, mujoco.mjtObj.mjOBJ_BODY, "target")
    return float(w.model.body_subtreemass[body])


def _push_y(w: SimWorld, seconds: float) -> np.ndarray:
    """World-y position of the target relative to its start, per cycle, under a constant push."""
    body = mujoco.mj_name2id(w.model, mujoco.mjtObj.mjOBJ_BODY, "target")
    y0 = float(w.data.xpos[body, 1])
    w.data.xfrc_applied[body, 1] = PUSH_N
    out = []
    for _ in range(round(seconds / w.cycle_s)):
        w.step()
        out.append(float(w.data.xpos[body, 1]) - y0)
    return np.asarray(out)


def test_hose_holds_the_target_at_push_over_stiffness() -> None:
    y = _push_y(_world(), 8.0)
    assert y[-1] == pytest.approx(PUSH_N / K_NPM, rel=0.01)


def test_hose_rings_at_the_damped_frequency_and_decays_at_c_over_2m() -> None:
    w = _world()
    m = _moving_mass_kg(w)
    y = _push_y(w, 3.0) - PUSH_N / K_NPM
    t = (np.arange(y.size) + 1) * w.cycle_s
    # successive maxima of the ringing: their spacing is the damped period,
    # their ratio the decay over one period
    peaks = [i for i in range(1, y.size - 1) if y[i] > y[i - 1] and y[i] >= y[i + 1] and y[i] > 0]
    assert len(peaks) >= 2
    period = t[peaks[1]] - t[peaks[0]]
    omega_d = math.sqrt(K_NPM / m - (C_NSPM / (2 * m)) ** 2)
    assert period == pytest.approx(2 * math.pi / omega_d, rel=0.02)
    decay = y[peaks[1]] / y[peaks[0]]
    assert decay == pytest.approx(math.exp(-C_NSPM / (2 * m) * period), rel=0.05)


def test_bed_friction_holds_a_push_below_mu_m_g_against_the_hose() -> None:
    """With friction, a push below mu m g does not move the target at all (static friction)."""
    w = _world(mu=0.01)
    m = _moving_mass_kg(w)
    assert PUSH_N < 0.01 * m * 9.81
    y = _push_y(w, 1.0)
    assert abs(y[-1]) < 1e-4
