"""The rendered target's physics without a carrier: the free body's integrators against
closed forms, and the delayed unilateral contact's solver against its limits and the
linear closed form (docs/hil.md)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from drivers.carrier.body import FreeBody, rotation_exp, rotation_log
from drivers.description.impact import restitution_of
from ffexp.hil.reference import critical_delay, delayed_restitution, linear_restitution


def _block() -> FreeBody:
    inertia = np.diag([0.065, 0.065, 0.125])
    return FreeBody(12.0, inertia, np.zeros(3), np.eye(3), np.zeros(3), np.zeros(3))


@pytest.mark.parametrize("integrator", ["symplectic", "explicit"])
def test_constant_force_gives_the_discrete_closed_form(integrator: str) -> None:
    body, f, dt, n = _block(), np.array([3.0, -1.0, 0.5]), 0.002, 250
    for _ in range(n):
        body.step(f, np.zeros(3), dt, integrator)  # type: ignore[arg-type]
    a = f / 12.0
    np.testing.assert_allclose(body.velocity_mps, a * n * dt, rtol=1e-12)
    # sum of v_k dt: k = 1..n (symplectic) or 0..n-1 (explicit): one cycle apart
    steps = n * (n + 1) / 2 if integrator == "symplectic" else n * (n - 1) / 2
    np.testing.assert_allclose(body.position_m, a * dt * dt * steps, rtol=1e-12)


def test_spin_about_a_principal_axis_keeps_its_energy_and_axis() -> None:
    body = FreeBody(12.0, np.diag([0.065, 0.065, 0.125]), np.zeros(3), np.eye(3),
                    np.zeros(3), np.array([0.0, 0.0, 0.3]))
    e0 = body.kinetic_energy_j()
    for _ in range(1000):
        body.step(np.zeros(3), np.zeros(3), 0.002)
    assert body.kinetic_energy_j() == pytest.approx(e0, rel=1e-12)
    np.testing.assert_allclose(body.angular_radps, [0.0, 0.0, 0.3], atol=1e-12)
    assert rotation_log(body.rotation)[2] == pytest.approx(0.3 * 2.0, abs=1e-9)  # 2 s at 0.3/s


def test_energy_in_a_moving_frame() -> None:
    body = FreeBody(2.0, np.eye(3), np.zeros(3), np.eye(3), np.array([1.0, 0.0, 0.0]),
                    np.zeros(3))
    assert body.kinetic_energy_j(np.array([0.25, 0.0, 0.0])) == pytest.approx(0.5 * 2 * 0.75**2)


def test_rotation_exp_and_log_are_inverse() -> None:
    for v in ([0.1, -0.2, 0.3], [0.0, 0.0, 0.0], [1e-10, 0.0, 0.0], [2.0, 1.0, -0.5]):
        rot = rotation_exp(np.array(v))
        np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-12)
        np.testing.assert_allclose(rotation_log(rot), v, atol=1e-9)


@pytest.mark.parametrize("zeta", [0.0, 0.05, 0.2, 0.6])
def test_without_delay_the_solver_gives_the_clamped_contact_closed_form(zeta: float) -> None:
    m, k = 12.0, 2e4
    c = 2.0 * zeta * math.sqrt(k * m)
    assert delayed_restitution(m, k, c, 0.0, 0.1) == pytest.approx(restitution_of(zeta),
                                                                    rel=1e-6)


@pytest.mark.parametrize("wn_tau", [0.02, 0.05, 0.1, 0.2])
def test_an_elastic_contact_gains_as_the_linear_closed_form_says(wn_tau: float) -> None:
    # zeta = 0: no clamping of a damper force, so the linear form holds to second order
    e = delayed_restitution(1.0, 1.0, 0.0, wn_tau)
    assert e == pytest.approx(linear_restitution(0.0, wn_tau), rel=0.01)
    assert e == pytest.approx(math.exp(math.pi * wn_tau / 2.0), rel=0.01)


def test_the_delay_only_adds_energy_and_the_result_is_scale_free() -> None:
    m, k, c = 12.0, 2e4, 250.0
    wn = math.sqrt(k / m)
    es = [delayed_restitution(m, k, c, x / wn, 0.1) for x in (0.0, 0.05, 0.1, 0.2, 0.3)]
    assert all(b is not None and a is not None and b > a for a, b in itertools.pairwise(es))
    assert delayed_restitution(m, k, c, 0.1 / wn, 1.0) == pytest.approx(es[2], rel=1e-6)


def test_critical_delay_is_a_root_on_the_imaginary_axis() -> None:
    m, k, c = 12.0, 2e4, 250.0
    tau = critical_delay(m, k, c)
    wc = math.sqrt((c * c + math.sqrt(c**4 + 4 * m * m * k * k)) / (2 * m * m))
    s = 1j * wc
    residual = m * s * s + (c * s + k) * np.exp(-s * tau)
    assert abs(residual) < 1e-9 * k
    assert tau == pytest.approx(c / k, rel=0.2)  # about c / k for a light damper
