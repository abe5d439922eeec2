"""The pure maths of the friction estimate (no video)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ffexp.friction.fit import (
    G_MPS2,
    FitError,
    detect_sigma_a,
    estimate_friction,
    find_sliding_interval,
    fit_quadratic,
    lag1_autocorrelation,
    project_on_motion,
    trim_at_fitted_stop,
)

FPS = 50.0


def _slide(a: float, v0: float, t: np.ndarray, t_imp: float) -> np.ndarray:
    tau = np.clip(t - t_imp, 0.0, None)
    if a > 0:
        tau = np.minimum(tau, v0 / a)
    return v0 * tau - 0.5 * a * tau**2


@settings(max_examples=50, deadline=None)
@given(
    a=st.floats(-2.0, 2.0),
    v0=st.floats(-1.0, 1.0),
    x0=st.floats(-1.0, 1.0),
    n=st.integers(4, 300),
    t0=st.floats(0.0, 100.0),
)
def test_noise_free_parabola_is_recovered(
    a: float, v0: float, x0: float, n: int, t0: float
) -> None:
    t = t0 + np.arange(n) / FPS
    x = x0 + v0 * (t - t0) - 0.5 * a * (t - t0) ** 2
    fit = fit_quadratic(t, x)
    assert fit.decel_mps2 == pytest.approx(a, abs=1e-6)
    assert fit.v_start_mps == pytest.approx(v0, abs=1e-6)
    assert fit.position_m(t) == pytest.approx(x, abs=1e-9)


def test_closed_form_sigma_a_matches_monte_carlo_and_fit_covariance() -> None:
    rng = np.random.default_rng(11)
    n, sigma = 200, 20e-6
    t = np.arange(n) / FPS
    window_s = n / FPS
    truth = 0.1 * t - 0.5 * 0.05 * t**2
    fits = [fit_quadratic(t, truth + rng.normal(0.0, sigma, n)) for _ in range(600)]
    a_hat = np.array([f.decel_mps2 for f in fits])
    formula = detect_sigma_a(sigma, n, window_s)
    assert float(np.std(a_hat)) == pytest.approx(formula, rel=0.1)
    median_fit_std = float(np.median([f.decel_std_mps2 for f in fits]))
    assert median_fit_std == pytest.approx(formula, rel=0.1)
    # and the formula's scaling: 4x the window, 1/32 of the error at the same rate
    assert detect_sigma_a(sigma, 4 * n, 4 * window_s) == pytest.approx(formula / 32.0)


def test_interval_covers_truth_at_its_nominal_rate_for_white_noise() -> None:
    rng = np.random.default_rng(5)
    mu = 0.01
    t = np.arange(30) / FPS
    x = _slide(mu * G_MPS2, 0.2, t, -1.0)
    covered = 0
    trials = 600
    for _ in range(trials):
        est = estimate_friction(t, x + rng.normal(0.0, 30e-6, t.size))
        covered += est.mu_low <= mu <= est.mu_high
    assert 0.92 <= covered / trials <= 0.98


def test_zero_friction_gives_a_bound_consistent_with_the_formula() -> None:
    rng = np.random.default_rng(3)
    n, sigma = 100, 15e-6
    t = np.arange(n) / FPS
    x = 0.1 * t + rng.normal(0.0, sigma, n)
    est = estimate_friction(t, x)
    fit = est.fit
    assert not est.significant
    assert est.mu_upper_bound == pytest.approx(max(est.mu, 0.0) + est.t_quantile * est.mu_std)
    expected = est.t_quantile * math.sqrt(720.0 / n) * sigma / (n / FPS) ** 2 / G_MPS2
    # the detectability limit uses the residual noise, which estimates sigma
    assert est.mu_detect_limit == pytest.approx(expected, rel=0.25)
    assert est.mu_std * G_MPS2 == pytest.approx(detect_sigma_a(sigma, n, fit.window_s), rel=0.25)
    assert est.mu_detect_limit <= est.mu_upper_bound <= 3.0 * est.mu_detect_limit


def test_significant_friction_is_flagged() -> None:
    rng = np.random.default_rng(4)
    t = np.arange(80) / FPS
    x = _slide(0.02 * G_MPS2, 0.5, t, -1.0) + rng.normal(0.0, 10e-6, t.size)
    est = estimate_friction(t, x)
    assert est.significant
    assert est.mu_low < 0.02 < est.mu_high
    assert est.mu_upper_bound == pytest.approx(est.mu_high)


def test_autocorrelated_residuals_inflate_the_variance() -> None:
    rng = np.random.default_rng(8)
    n = 200
    t = np.arange(n) / FPS
    white = rng.normal(0.0, 10e-6, n)
    ar = np.zeros(n)
    for i in range(1, n):
        ar[i] = 0.7 * ar[i - 1] + white[i]
    fit = fit_quadratic(t, 0.1 * t + ar)
    assert fit.rho1 > 0.4
    assert fit.inflation == pytest.approx((1 + fit.rho1) / (1 - fit.rho1))
    assert fit_quadratic(t, 0.1 * t + white).inflation < fit.inflation
    assert lag1_autocorrelation(np.array([1.0, 2.0])) == 0.0


def test_too_few_frames_is_an_error() -> None:
    with pytest.raises(FitError, match="only 3 frames"):
        fit_quadratic(np.arange(3.0), np.zeros(3))


def test_projection_finds_the_motion_direction() -> None:
    rng = np.random.default_rng(1)
    ang = math.radians(-35.0)
    s = np.linspace(0.0, 0.3, 50)
    pos = np.stack([0.2 + s * math.cos(ang), 0.1 + s * math.sin(ang)], axis=1)
    pos += rng.normal(0.0, 1e-5, pos.shape)
    proj, direction = project_on_motion(pos)
    assert direction == pytest.approx([math.cos(ang), math.sin(ang)], abs=1e-3)
    assert proj[-1] == pytest.approx(0.3, abs=1e-3)


def _track(mu: float, v0: float, duration_s: float, t_imp: float, seed: int, noise: float = 10e-6):
    rng = np.random.default_rng(seed)
    t = np.arange(round(duration_s * FPS)) / FPS
    return t, _slide(mu * G_MPS2, v0, t, t_imp) + rng.normal(0.0, noise, t.size)


def test_interval_after_impulse_until_stop() -> None:
    t_imp = 0.3137
    mu, v0 = 0.02, 0.1
    t, s = _track(mu, v0, 1.5, t_imp, seed=2)
    t_stop = t_imp + v0 / (mu * G_MPS2)
    iv = find_sliding_interval(t, s)
    assert iv.end_reason == "stopped"
    assert t[iv.start] > t_imp
    assert t[iv.start] - t_imp < 0.1
    assert t[iv.end] < t_stop
    assert t_stop - t[iv.end] < 0.1
    est = estimate_friction(t[iv.start : iv.end + 1], s[iv.start : iv.end + 1])
    assert est.mu_low <= mu <= est.mu_high


def test_interval_to_end_of_video_or_leaving() -> None:
    t, s = _track(0.005, 0.2, 1.0, 0.2, seed=3)
    assert find_sliding_interval(t, s).end_reason == "end_of_video"
    left = find_sliding_interval(t, s, left_frame=True)
    assert left.end_reason == "left_frame"
    assert left.end == t.size - 1


def test_push_of_finite_length_is_skipped() -> None:
    # accelerated for 0.1 s (a push), then free sliding
    t = np.arange(100) / FPS
    t_push, t_end = 0.3, 0.4
    a_push, a_fric = 2.0, 0.1
    v1 = a_push * (t_end - t_push)
    x_end = 0.5 * a_push * (t_end - t_push) ** 2
    s = np.where(
        t < t_push,
        0.0,
        np.where(
            t < t_end,
            0.5 * a_push * (t - t_push) ** 2,
            x_end + v1 * (t - t_end) - 0.5 * a_fric * (t - t_end) ** 2,
        ),
    )
    s = s + np.random.default_rng(0).normal(0.0, 5e-6, t.size)
    iv = find_sliding_interval(t, s)
    assert t[iv.start] >= t_end - 1e-9
    est = estimate_friction(t[iv.start : iv.end + 1], s[iv.start : iv.end + 1])
    assert est.fit.decel_mps2 == pytest.approx(a_fric, rel=0.05)


def test_no_motion_and_too_short_slides_are_errors() -> None:
    rng = np.random.default_rng(0)
    t = np.arange(50) / FPS
    with pytest.raises(FitError, match="does not move"):
        find_sliding_interval(t, rng.normal(0.0, 1e-5, t.size))
    # stops after two frames of sliding
    t2, s2 = _track(0.5, 0.05, 1.0, 0.3, seed=1, noise=1e-6)
    with pytest.raises(FitError, match="stops after"):
        find_sliding_interval(t2, s2)


def test_a_stop_just_before_the_end_is_cut_at_the_fitted_stop() -> None:
    t_imp, mu, v0 = 0.2137, 0.03, 0.1
    t_stop = t_imp + v0 / (mu * G_MPS2)
    t, s = _track(mu, v0, t_stop + 0.05, t_imp, seed=9, noise=5e-6)  # two frames at rest
    iv = find_sliding_interval(t, s)
    assert iv.end_reason == "end_of_video"  # too short a rest to be seen
    cut = trim_at_fitted_stop(t, s, iv)
    assert cut.end_reason == "stopped"
    assert t[cut.end] < t_stop
    est = estimate_friction(t[cut.start : cut.end + 1], s[cut.start : cut.end + 1])
    assert est.mu_low <= mu <= est.mu_high
    # a target still sliding at the end is left alone
    t2, s2 = _track(0.005, 0.2, 1.0, 0.2, seed=3)
    iv2 = find_sliding_interval(t2, s2)
    assert trim_at_fitted_stop(t2, s2, iv2) == iv2


def test_pooled_noise_keeps_coverage_and_narrows_short_windows() -> None:
    rng = np.random.default_rng(21)
    mu, sigma = 0.05, 10e-6
    t = np.arange(5) / FPS
    x = _slide(mu * G_MPS2, 0.05, t, -0.001)
    covered = 0
    widths_alone, widths_pooled = [], []
    trials = 600
    for _ in range(trials):
        xs = x + rng.normal(0.0, sigma, t.size)
        other = float(np.std(rng.normal(0.0, sigma, 40), ddof=1))  # same noise, 39 dof
        pooled = estimate_friction(t, xs, noise_m=other, noise_dof=39)
        alone = estimate_friction(t, xs)
        covered += pooled.mu_low <= mu <= pooled.mu_high
        widths_alone.append(alone.mu_high - alone.mu_low)
        widths_pooled.append(pooled.mu_high - pooled.mu_low)
        assert pooled.dof == alone.dof + 39
    assert 0.92 <= covered / trials <= 0.98
    # t(0.975; 2) = 4.30 against t(0.975; 41) = 2.02, and a median s of ~0.83 sigma
    # on 2 dof: the pooled interval is about 0.57 times as wide
    assert np.median(widths_pooled) < 0.7 * np.median(widths_alone)
