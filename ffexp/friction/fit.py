"""Pure maths of the friction estimate: sliding interval, quadratic fit, bound.

No I/O and no global state. Positions are in metres, times in seconds.

The model on the free-sliding interval is ``x(t) = x0 + v0 τ - a τ² / 2`` with
``τ = t - t_c`` (time centred on the window, so ``a`` is uncorrelated with
``x0`` and ``v0``), fitted by ordinary least squares. ``a > 0`` is a
deceleration along the motion direction and ``mu = a / g``.

Uncertainty (documented choice): the 95 % interval is Student-t with
``N - 3`` degrees of freedom on the least-squares standard error of ``a``,
whose residual variance is inflated by the AR(1) factor ``(1 + ρ) / (1 - ρ)``
when the lag-1 autocorrelation ``ρ`` of the residuals is positive and
measurable (``N >= 20``). The detectability bound is the closed form
``σ_a = sqrt(720 / N) σ_x / T²`` for ``N`` frames over a window ``T = N Δt``
with residual noise ``σ_x``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np
import numpy.typing as npt
from scipy import stats

from drivers.base.types import F64

BoolArray = npt.NDArray[np.bool_]

#: Standard gravity (m/s²).
G_MPS2 = 9.80665

#: Fewest frames a fit accepts (one residual degree of freedom).
MIN_FIT_FRAMES = 4

EndReason = Literal["stopped", "left_frame", "end_of_video", "user"]


class FitError(ValueError):
    """The track cannot be fitted (no motion, too few frames, bad window)."""


def detect_sigma_a(residual_std_m: float, n_frames: int, window_s: float) -> float:
    """Closed-form standard error of the deceleration of a quadratic fit.

    For ``n_frames`` equally spaced samples over a window ``window_s`` with
    white position noise ``residual_std_m``: ``sqrt(720 / N) σ_x / T²``.

    Args:
        residual_std_m: position noise (m).
        n_frames: number of samples N.
        window_s: window length T (s), N frame periods.

    Returns:
        The standard error of ``a`` (m/s²).
    """
    if n_frames <= 0 or window_s <= 0.0:
        raise FitError("the window must hold at least one frame and have a positive length")
    return math.sqrt(720.0 / n_frames) * residual_std_m / window_s**2


@dataclass(frozen=True)
class QuadraticFit:
    """Least-squares fit of ``x0 + v0 τ - a τ²/2`` with ``τ = t - t_centre_s``."""

    t_centre_s: float
    x_centre_m: float
    v_centre_mps: float
    decel_mps2: float
    #: Covariance of ``(x_centre_m, v_centre_mps, decel_mps2)``, already inflated.
    cov: F64
    #: ``(XᵀX)⁻¹`` of the design: ``cov = cov_unit σ² inflation``.
    cov_unit: F64
    residuals_m: F64
    residual_std_m: float
    #: Lag-1 autocorrelation of the residuals (0 when not measured).
    rho1: float
    #: Variance inflation applied to ``cov`` for residual correlation (>= 1).
    inflation: float
    n_frames: int
    #: N frame periods: the span of the samples plus one frame period (s).
    window_s: float
    t_start_s: float
    t_end_s: float

    @property
    def dof(self) -> int:
        """Residual degrees of freedom."""
        return self.n_frames - 3

    @property
    def decel_std_mps2(self) -> float:
        """Standard error of the deceleration (m/s²)."""
        return math.sqrt(float(self.cov[2, 2]))

    @property
    def v_start_mps(self) -> float:
        """Fitted speed at the first sample of the window (m/s)."""
        return self.v_centre_mps + self.decel_mps2 * (self.t_centre_s - self.t_start_s)

    def position_m(self, t_s: F64) -> F64:
        """Fitted position at times ``t_s``."""
        tau = np.asarray(t_s, dtype=np.float64) - self.t_centre_s
        return self.x_centre_m + self.v_centre_mps * tau - 0.5 * self.decel_mps2 * tau**2

    def velocity_mps(self, t_s: F64) -> F64:
        """Fitted velocity at times ``t_s``."""
        tau = np.asarray(t_s, dtype=np.float64) - self.t_centre_s
        return self.v_centre_mps - self.decel_mps2 * tau

    def position_std_m(self, t_s: F64) -> F64:
        """Standard error of the fitted position (the curve, not a new sample)."""
        tau = np.asarray(t_s, dtype=np.float64) - self.t_centre_s
        jac = np.stack([np.ones_like(tau), tau, -0.5 * tau**2], axis=-1)
        var = np.einsum("...i,ij,...j->...", jac, self.cov, jac)
        return np.asarray(np.sqrt(np.maximum(var, 0.0)), np.float64)

    def velocity_std_m(self, t_s: F64) -> F64:
        """Standard error of the fitted velocity."""
        tau = np.asarray(t_s, dtype=np.float64) - self.t_centre_s
        jac = np.stack([np.zeros_like(tau), np.ones_like(tau), -tau], axis=-1)
        var = np.einsum("...i,ij,...j->...", jac, self.cov, jac)
        return np.asarray(np.sqrt(np.maximum(var, 0.0)), np.float64)


def lag1_autocorrelation(residuals: F64) -> float:
    """Lag-1 autocorrelation of a residual series (0 for fewer than 3 samples)."""
    r = np.asarray(residuals, dtype=np.float64)
    if r.size < 3:
        return 0.0
    r = r - r.mean()
    denom = float(np.dot(r, r))
    if denom <= 0.0:
        return 0.0
    return float(np.dot(r[:-1], r[1:]) / denom)


def fit_quadratic(
    t_s: F64, x_m: F64, *, min_frames_for_rho: int = 20
) -> QuadraticFit:
    """Fit ``x0 + v0 τ - a τ²/2`` (τ centred) by least squares.

    Args:
        t_s: sample times (s), increasing.
        x_m: positions along the motion direction (m).
        min_frames_for_rho: fewest samples for which the residual
            autocorrelation is measured and used to inflate the covariance.

    Returns:
        The fit with its covariance.

    Raises:
        FitError: fewer than :data:`MIN_FIT_FRAMES` samples or degenerate times.
    """
    t = np.asarray(t_s, dtype=np.float64)
    x = np.asarray(x_m, dtype=np.float64)
    n = int(t.size)
    if n != x.size:
        raise FitError("times and positions differ in length")
    if n < MIN_FIT_FRAMES:
        raise FitError(f"only {n} frames to fit (need at least {MIN_FIT_FRAMES})")
    t_c = 0.5 * (float(t[0]) + float(t[-1]))
    tau = t - t_c
    design = np.stack([np.ones_like(tau), tau, -0.5 * tau**2], axis=1)
    coef, _, rank, _ = np.linalg.lstsq(design, x, rcond=None)
    if rank < 3:
        raise FitError("the frame times are degenerate")
    residuals = x - design @ coef
    dof = n - 3
    s2 = float(np.dot(residuals, residuals)) / dof
    rho = lag1_autocorrelation(residuals) if n >= min_frames_for_rho else 0.0
    rho_c = min(rho, 0.9)
    inflation = (1.0 + rho_c) / (1.0 - rho_c) if rho_c > 0.0 else 1.0
    cov_unit = np.asarray(np.linalg.inv(design.T @ design), np.float64)
    cov = cov_unit * s2 * inflation
    dt = float(np.median(np.diff(t)))
    return QuadraticFit(
        t_centre_s=t_c,
        x_centre_m=float(coef[0]),
        v_centre_mps=float(coef[1]),
        decel_mps2=float(coef[2]),
        cov=cov,
        cov_unit=cov_unit,
        residuals_m=residuals,
        residual_std_m=math.sqrt(s2),
        rho1=rho,
        inflation=inflation,
        n_frames=n,
        window_s=float(t[-1] - t[0]) + dt,
        t_start_s=float(t[0]),
        t_end_s=float(t[-1]),
    )


@dataclass(frozen=True)
class SlidingInterval:
    """The free-sliding part of a track, as sample indices ``[start, end]`` (inclusive)."""

    start: int
    end: int
    end_reason: EndReason
    #: Index of the first sample that is clearly displaced from rest.
    onset: int
    #: Position noise estimated from the track (m), used for the thresholds.
    noise_m: float


def project_on_motion(pos_m: F64) -> tuple[F64, F64]:
    """Project a 2-D track on its principal direction of motion.

    Args:
        pos_m: (N, 2) positions in metres (all valid).

    Returns:
        ``(s_m, direction)``: the scalar coordinate along the unit vector
        ``direction``, oriented so that the track moves towards positive ``s``,
        with ``s = 0`` at the first sample.
    """
    p = np.asarray(pos_m, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2 or p.shape[0] < 2:
        raise FitError("a track needs at least two 2-D positions")
    centred = p - p.mean(axis=0)
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    direction = vt[0]
    if float(np.dot(p[-1] - p[0], direction)) < 0.0:
        direction = -direction
    s = (p - p[0]) @ direction
    return s, direction


def robust_noise(s_m: F64) -> float:
    """Position noise of a smooth track from its second differences (MAD).

    A quadratic has a constant second difference, so its MAD keeps only the
    noise: ``σ = 1.4826 MAD(Δ²s) / sqrt(6)``.
    """
    s = np.asarray(s_m, dtype=np.float64)
    if s.size < 5:
        return 0.0
    d2 = np.diff(s, n=2)
    mad = float(np.median(np.abs(d2 - np.median(d2))))
    return 1.4826 * mad / math.sqrt(6.0)


def find_sliding_interval(
    t_s: F64,
    s_m: F64,
    *,
    left_frame: bool = False,
    k_onset: float = 6.0,
    k_stop: float = 3.0,
    push_window_s: float = 0.2,
    stop_check_s: float = 0.1,
    min_noise_m: float = 1e-7,
) -> SlidingInterval:
    """Find the free-sliding interval after the impulse in a 1-D track.

    The track is at rest, is set moving by an impulse (possibly a push of
    finite length), slides, and then stops, leaves the frame
    (``left_frame=True``: the track ends because the target left) or is cut
    by the end of the video.

    - onset: first sample displaced from the rest level by more than
      ``k_onset`` noise (and the next one too);
    - start: the first sample from the onset on whose frame-to-frame speed
      is within 3 noise of the largest over ``push_window_s`` (the end of a
      push of finite length; the onset itself for an impulse);
    - end: if the last ``stop_check_s`` of the track do not move (within
      ``k_onset`` noise), the target stopped, and the window ends just before
      the first sample within ``k_stop`` noise of the final position;
      otherwise at the last sample.

    Args:
        t_s: sample times (s).
        s_m: positions along the motion direction (m), moving towards +s.
        left_frame: the track ends because the target left the frame.
        k_onset: onset threshold in noise units.
        k_stop: stop-exclusion threshold in noise units.
        push_window_s: how long after the onset the push may still accelerate.
        stop_check_s: length of the final segment tested for rest.
        min_noise_m: floor of the noise estimate (noise-free synthetic tracks).

    Returns:
        The interval.

    Raises:
        FitError: no motion or too few frames of free sliding.
    """
    t = np.asarray(t_s, dtype=np.float64)
    s = np.asarray(s_m, dtype=np.float64)
    n = int(s.size)
    if n < MIN_FIT_FRAMES + 1:
        raise FitError(f"the track has only {n} frames")
    noise = max(robust_noise(s), min_noise_m)
    dt = float(np.median(np.diff(t)))
    rest_level = float(np.median(s[: min(5, n)]))
    thr = k_onset * noise
    away = (s - rest_level) > thr
    both = away[:-1] & away[1:]
    if left_frame and not bool(both.any()):
        # the target left the frame (almost) as soon as it moved
        raise FitError(
            f"the target leaves the frame after {int(away.sum())} frame(s) of free sliding "
            f"(need at least {MIN_FIT_FRAMES})"
        )
    if not bool(both.any()):
        raise FitError(
            f"the target does not move (displacement below {thr:.2e} m = {k_onset:g} x noise)"
        )
    onset = int(np.argmax(both))
    # Start: the end of the push, i.e. the first sample from which the
    # frame-to-frame speed no longer rises (within its noise) over the push window.
    speed = np.diff(s) / np.diff(t)
    n_push = max(1, round(push_window_s / dt))
    hi = min(onset + n_push, speed.size)
    speed_noise = 3.0 * math.sqrt(2.0) * noise / dt
    start = onset
    if hi > onset:
        top = float(np.max(speed[onset:hi]))
        reach = np.flatnonzero(speed[onset:hi] >= top - speed_noise)
        start = onset + int(reach[0])
    end = n - 1
    reason: EndReason = "left_frame" if left_frame else "end_of_video"
    n_check = max(3, round(stop_check_s / dt))
    if not left_frame and n - start > n_check:
        tail = s[-n_check:]
        if float(tail.max() - tail.min()) < 2.0 * thr:
            final = float(np.median(tail))
            arrived = np.flatnonzero(final - s[start:] <= k_stop * noise)
            end = start + int(arrived[0]) - 1 if arrived.size else n - 1
            reason = "stopped"
    frames = end - start + 1
    if frames < MIN_FIT_FRAMES:
        what = {
            "stopped": "the target stops",
            "left_frame": "the target leaves the frame",
            "end_of_video": "the video ends",
        }.get(reason, "the window ends")
        raise FitError(
            f"{what} after {frames} frame(s) of free sliding (need at least {MIN_FIT_FRAMES})"
        )
    return SlidingInterval(start=start, end=end, end_reason=reason, onset=onset, noise_m=noise)


def trim_at_fitted_stop(
    t_s: F64, s_m: F64, interval: SlidingInterval, *, max_iter: int = 5
) -> SlidingInterval:
    """Cut the window at the stop predicted by its own fit.

    A target slowed by friction stops when its fitted velocity reaches zero
    (the vertex of the parabola) and stays there; samples after that instant
    are not free sliding even when too few of them remain to be seen as a
    rest (a stop just before the end of the video). Refit until the vertex
    is after the last sample.

    Returns:
        The interval, ending ``"stopped"`` if it was cut.
    """
    t = np.asarray(t_s, dtype=np.float64)
    s = np.asarray(s_m, dtype=np.float64)
    start, end, reason = interval.start, interval.end, interval.end_reason
    for _ in range(max_iter):
        fit = fit_quadratic(t[start : end + 1], s[start : end + 1])
        if fit.decel_mps2 <= 0.0:
            break
        t_stop = fit.t_centre_s + fit.v_centre_mps / fit.decel_mps2
        if t_stop >= t[end]:
            break
        new_end = int(np.searchsorted(t, t_stop, side="left")) - 1
        if new_end - start + 1 < MIN_FIT_FRAMES or new_end >= end:
            break
        end, reason = new_end, "stopped"
    return SlidingInterval(
        start=start, end=end, end_reason=reason, onset=interval.onset, noise_m=interval.noise_m
    )


@dataclass(frozen=True)
class FrictionEstimate:
    """Deceleration, friction coefficient, its interval and its bound."""

    fit: QuadraticFit
    g_mps2: float
    confidence: float
    mu: float
    mu_std: float
    mu_low: float
    mu_high: float
    #: One-sided upper limit: ``max(mu, 0) + t_q mu_std`` (see module docstring).
    mu_upper_bound: float
    #: Smallest |mu| distinguishable from 0: ``t_q σ_a / g`` with the closed form σ_a.
    mu_detect_limit: float
    #: Closed-form σ_a from residual noise, N and T (m/s²).
    sigma_a_formula_mps2: float
    significant: bool
    t_quantile: float
    #: Position noise used for the uncertainty: pooled, inflated (m).
    sigma_x_m: float
    #: Degrees of freedom of ``sigma_x_m`` (window residuals + pooled noise).
    dof: float


def estimate_friction(
    t_s: F64,
    x_m: F64,
    *,
    g_mps2: float = G_MPS2,
    confidence: float = 0.95,
    noise_m: float | None = None,
    noise_dof: float = 0.0,
) -> FrictionEstimate:
    """Fit the sliding window and turn the deceleration into ``mu``.

    ``significant`` is true when the interval of ``mu`` lies above 0
    (friction detected); an interval below 0 means the target sped up (a
    tilted table or a push), which is not friction either.
    ``mu_upper_bound`` is ``max(mu, 0) + t_q mu_std``: the upper end of the
    interval, never below the detectability of this window (a negative
    estimate would otherwise give a bound that claims more than the data can
    resolve); it is the number to report as ``mu < bound`` when the estimate
    is not significant.

    The position noise is the window's residual variance, pooled (when
    ``noise_m`` is given) with an independent estimate of the same tracking
    noise from more frames, weighted by degrees of freedom; a window of a
    few frames has almost no residual degrees of freedom of its own.

    Args:
        t_s: times of the sliding window (s).
        x_m: positions along the motion direction (m).
        g_mps2: gravity (m/s²).
        confidence: two-sided confidence level of the interval.
        noise_m: independent estimate of the position noise (m), if any.
        noise_dof: its degrees of freedom.

    Returns:
        The estimate.
    """
    if not 0.0 < confidence < 1.0:
        raise FitError("confidence must be between 0 and 1")
    fit = fit_quadratic(t_s, x_m)
    s2 = fit.residual_std_m**2
    dof = float(fit.dof)
    if noise_m is not None and noise_m > 0.0 and noise_dof > 0.0:
        s2 = (dof * s2 + noise_dof * noise_m**2) / (dof + noise_dof)
        dof += noise_dof
        fit = replace(fit, cov=fit.cov_unit * s2 * fit.inflation)
    sigma_x = math.sqrt(s2 * fit.inflation)
    tq = float(stats.t.ppf(0.5 + 0.5 * confidence, dof))
    mu = fit.decel_mps2 / g_mps2
    mu_std = fit.decel_std_mps2 / g_mps2
    sigma_formula = detect_sigma_a(sigma_x, fit.n_frames, fit.window_s)
    return FrictionEstimate(
        fit=fit,
        g_mps2=g_mps2,
        confidence=confidence,
        mu=mu,
        mu_std=mu_std,
        mu_low=mu - tq * mu_std,
        mu_high=mu + tq * mu_std,
        mu_upper_bound=max(mu, 0.0) + tq * mu_std,
        mu_detect_limit=tq * sigma_formula / g_mps2,
        sigma_a_formula_mps2=sigma_formula,
        significant=mu > tq * mu_std,
        t_quantile=tq,
        sigma_x_m=sigma_x,
        dof=dof,
    )
