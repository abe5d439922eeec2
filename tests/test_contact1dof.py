"""The Section III model against closed forms, conservation laws and the paper's trends."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.config import load_model
from ffexp.contact1dof import ContactParams, simulate, summarize
from ffexp.contact1dof.sweep import SweepProtocol, run_sweep

PROTOCOLS = Path(__file__).resolve().parents[1] / "protocols"


def closed_form_p(params: ContactParams, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Penetration and its rate from the scalar 2nd-order ODE of p.

    Subtracting the two equations of motion gives
    p'' + (b_c/mu + b_ri/m_ri) p' + (k_c/mu + k_ri/m_ri) p = 0, mu = m_ri m_t/(m_ri + m_t),
    with p(0) = 0, p'(0) = v0; solved here by hand for all three damping cases.
    """
    mu = params.m_ri * params.m_t / (params.m_ri + params.m_t)
    c = params.b_c / mu + params.b_ri / params.m_ri
    k = params.k_c / mu + params.k_ri / params.m_ri
    sigma = c / 2.0
    disc = sigma**2 - k
    v0 = params.v0
    if disc < -1e-12:
        wd = np.sqrt(-disc)
        e = np.exp(-sigma * t)
        p = v0 * e * np.sin(wd * t) / wd
        pd = v0 * e * (np.cos(wd * t) - sigma * np.sin(wd * t) / wd)
    elif disc > 1e-12:
        r = np.sqrt(disc)
        l1, l2 = -sigma + r, -sigma - r
        p = v0 * (np.exp(l1 * t) - np.exp(l2 * t)) / (l1 - l2)
        pd = v0 * (l1 * np.exp(l1 * t) - l2 * np.exp(l2 * t)) / (l1 - l2)
    else:
        p = v0 * t * np.exp(-sigma * t)
        pd = v0 * (1.0 - sigma * t) * np.exp(-sigma * t)
    return p, pd


CASES = [
    ContactParams(),  # sim2 with k_ri = 0: over-damped relative motion
    ContactParams(m_ri=11, m_t=9, k_ri=300, b_ri=40),  # the CLI example
    ContactParams(m_ri=60, m_t=15, b_ri=100),  # high mass ratio: under-damped
    ContactParams(m_ri=7.5, m_t=25, b_ri=5),  # sim3, low damping
    ContactParams(m_ri=7.5, m_t=15, k_ri=3000),  # stiff manipulator
]


@pytest.mark.parametrize("params", CASES)
def test_matches_closed_form(params: ContactParams) -> None:
    traj = simulate(params, duration_s=3.0, dt_s=1e-3)
    p, pd = closed_form_p(params, traj.t_s)
    scale_p = np.max(np.abs(p))
    assert np.max(np.abs(traj.p - p)) <= 1e-6 * scale_p
    f_c = params.k_c * p + params.b_c * pd
    assert np.max(np.abs(traj.f_c - f_c)) <= 1e-6 * np.max(np.abs(f_c))


def test_closed_form_critical_damping() -> None:
    # choose b_ri so that (c/2)^2 = k exactly: the repeated-root branch
    m_ri, m_t, k_c, b_c = 5.0, 10.0, 250.0, 20.0
    mu = m_ri * m_t / (m_ri + m_t)
    b_ri = (2.0 * np.sqrt(k_c / mu) - b_c / mu) * m_ri
    params = ContactParams(m_ri=m_ri, m_t=m_t, k_c=k_c, b_c=b_c, b_ri=b_ri)
    traj = simulate(params, 2.0, 1e-3)
    p, _ = closed_form_p(params, traj.t_s)
    assert np.max(np.abs(traj.p - p)) <= 1e-6 * np.max(np.abs(p))


@settings(max_examples=30, deadline=None)
@given(
    m_ri=st.floats(0.5, 80.0),
    m_t=st.floats(0.5, 80.0),
    k_ri=st.floats(0.0, 3000.0),
    b_ri=st.floats(0.0, 300.0),
)
def test_momentum_balance_holds_at_every_sample(
    m_ri: float, m_t: float, k_ri: float, b_ri: float
) -> None:
    """d/dt (m_ri v_i + m_t v_t) = -(k_ri p + b_ri p'): only the manipulator's
    passive spring and damper exchange momentum with the outside."""
    params = ContactParams(m_ri=m_ri, m_t=m_t, k_ri=k_ri, b_ri=b_ri)
    traj = simulate(params, 1.0, 1e-3)
    momentum = m_ri * traj.v_i + m_t * traj.v_t
    # the integral of p by the trapezoidal rule errs by at most T dt^2/12 max|p''|
    dt = 1e-3
    int_p = np.concatenate([[0.0], np.cumsum((traj.p[1:] + traj.p[:-1]) / 2.0) * dt])
    p_dd = np.max(np.abs(np.gradient(np.gradient(traj.p, dt), dt)))
    expected = m_ri * params.v0 - b_ri * traj.p - k_ri * int_p
    tol = 1e-9 * m_ri * params.v0 + 2.0 * k_ri * 1.0 * dt**2 / 12.0 * p_dd
    assert np.max(np.abs(momentum - expected)) <= tol


def test_final_common_velocity_without_stiffness() -> None:
    params = ContactParams(m_ri=7.5, m_t=15.0, k_ri=0.0)
    traj = simulate(params, duration_s=20.0, dt_s=1e-3)
    v_common = params.m_ri * params.v0 / (params.m_ri + params.m_t)
    assert traj.v_i[-1] == pytest.approx(v_common, abs=1e-6)
    assert traj.v_t[-1] == pytest.approx(v_common, abs=1e-6)


def test_friction_force_decelerates_the_pair() -> None:
    params = ContactParams(f_friction=2.0)
    traj = simulate(params, 10.0, 1e-3)
    # after the transient both bodies decelerate together at F_f / (m_ri + m_t)
    i0, i1 = 6000, 8000
    accel = (traj.v_t[i1] - traj.v_t[i0]) / (traj.t_s[i1] - traj.t_s[i0])
    assert accel == pytest.approx(-2.0 / (params.m_ri + params.m_t), rel=1e-3)


def load_sweep(name: str) -> SweepProtocol:
    return load_model(SweepProtocol, PROTOCOLS / f"sec3_{name}.toml")


def test_mass_ratio_observations() -> None:
    """High m_ri/m_t: larger peak and F_c < 0; low: damped, contact maintained."""
    proto = load_sweep("mass_ratio")
    results = run_sweep(proto)
    ratios = [r.params.m_ri / r.params.m_t for r in results]
    assert ratios == sorted(ratios)
    peaks = [r.summary.peak_f_c_n for r in results]
    assert all(b >= a for a, b in itertools.pairwise(peaks))
    assert peaks[-1] > 1.5 * peaks[0]
    low, high = results[0].summary, results[-1].summary
    assert not low.contact_broke and low.min_f_c_n >= 0.0
    assert high.contact_broke and high.min_f_c_n < 0.0
    # every ratio >= 1 breaks, every ratio <= 0.5 holds contact
    for r in results:
        ratio = r.params.m_ri / r.params.m_t
        if ratio >= 1.0:
            assert r.summary.contact_broke
        if ratio <= 0.5:
            assert not r.summary.contact_broke


def test_stiffness_observations() -> None:
    """Higher k_ri gives contact break, with ever deeper negative F_c."""
    results = run_sweep(load_sweep("stiffness"))
    k = [r.params.k_ri for r in results]
    assert k == sorted(k)
    assert not results[0].summary.contact_broke
    assert results[-1].summary.contact_broke
    mins = [r.summary.min_f_c_n for r in results]
    assert all(b <= a for a, b in itertools.pairwise(mins))
    assert mins[-1] < 0.0


def test_damping_observations() -> None:
    """Higher b_ri (below critical damping) decays faster."""
    results = run_sweep(load_sweep("damping"))
    b = [r.params.b_ri for r in results]
    assert b == sorted(b)
    settle = [r.summary.settling_time_s for r in results]
    assert all(s is not None for s in settle)
    assert all(b_ < a for a, b_ in itertools.pairwise(settle))  # type: ignore[operator]
    undershoot = [r.summary.min_f_c_n for r in results]
    assert all(b_ >= a for a, b_ in itertools.pairwise(undershoot))


def test_unilateral_never_pulls() -> None:
    params = ContactParams(m_ri=60.0, m_t=15.0, unilateral=True)
    traj = simulate(params, 4.0, 1e-3)
    assert np.all(traj.f_c >= 0.0)
    summary = summarize(traj)
    assert summary.contact_broke
    # the bilateral model pulls at that moment: the clamp is what differs
    bilateral = simulate(params.model_copy(update={"unilateral": False}), 4.0, 1e-3)
    assert np.min(bilateral.f_c) < 0.0
    # while separated, no force acts on the target: it coasts at constant velocity
    free = np.flatnonzero(traj.f_c == 0.0)
    assert free.size > 10
    run_end = free[0] + int(np.argmax(np.diff(free) > 1)) if np.any(np.diff(free) > 1) else free[-1]
    coast = slice(free[0] + 1, run_end)
    assert run_end - free[0] > 10
    assert np.ptp(traj.v_t[coast]) < 1e-9


def test_unilateral_equals_bilateral_while_pushing() -> None:
    params = ContactParams()  # contact is maintained: the clamp never acts
    a = simulate(params, 3.0, 1e-3)
    b = simulate(params.model_copy(update={"unilateral": True}), 3.0, 1e-3)
    assert np.max(np.abs(a.p - b.p)) <= 1e-6 * np.max(np.abs(a.p))
    assert np.max(np.abs(a.f_c - b.f_c)) <= 1e-6 * np.max(np.abs(a.f_c))


def test_one_simulation_error_class() -> None:
    """A diverged physics simulation (raised by a driver) is caught as
    ``ffexp.errors.SimulationError``, and the 1-DOF model raises the same class."""
    import drivers.errors
    import ffexp.errors

    assert ffexp.errors.SimulationError is drivers.errors.SimulationError
    caught: list[str] = []
    try:
        raise drivers.errors.SimulationError("physics diverged at t = 0.1230 s")
    except ffexp.errors.SimulationError as exc:
        caught.append(str(exc))
    assert caught == ["physics diverged at t = 0.1230 s"]
    with pytest.raises(drivers.errors.DriverError, match=r"dt_s \(0.0 s\) <= duration_s"):
        simulate(ContactParams(), 1.0, 0.0)
    with pytest.raises(ffexp.errors.SimulationError, match="samples is too many"):
        simulate(ContactParams(), 1e3, 1e-5)
