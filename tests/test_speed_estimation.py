"""The estimator's hand-written per-axis Kalman filters against filterpy's general filter.

ffexp.estimation runs the wrench filter (12 states) and the motion filter
(18 states) as independent per-axis filters side by side, for speed. These
tests build the very same models as one filterpy KalmanFilter each and feed
both the same data: states and covariances must agree to rounding.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from filterpy.common import Q_discrete_white_noise
from filterpy.kalman import KalmanFilter
from scipy.spatial.transform import Rotation

from ffexp.estimation import (
    MotionFilter,
    MotionFilterConfig,
    WrenchFilter,
    WrenchFilterConfig,
)

CYCLE_S = 0.005


def _reference_wrench_filter(cfg: WrenchFilterConfig, tare: np.ndarray) -> KalmanFilter:
    r = np.diag(np.square(cfg.noise_std))
    bias_kf = KalmanFilter(dim_x=6, dim_z=6)
    bias_kf.x = np.zeros((6, 1))
    bias_kf.P = np.eye(6) * 100.0
    bias_kf.R = r
    bias_kf.H = np.eye(6)
    for z in tare:
        bias_kf.update(z)
    kf = KalmanFilter(dim_x=12, dim_z=6)
    kf.F = np.eye(12)
    kf.H = np.hstack([np.eye(6), np.eye(6)])
    kf.x = np.vstack([np.zeros((6, 1)), bias_kf.x])
    kf.P = np.zeros((12, 12))
    kf.P[:6, :6] = r
    kf.P[6:, 6:] = bias_kf.P
    kf.R = r
    return kf


def test_wrench_filter_equals_the_12_state_filterpy_filter() -> None:
    cfg = WrenchFilterConfig()
    rng = np.random.default_rng(3)
    std = np.asarray(cfg.noise_std)
    bias = np.array([0.5, -0.3, 1.0, 0.01, 0.02, -0.01])
    tare = bias + rng.normal(size=(300, 6)) * std
    wf = WrenchFilter(cfg)
    wf.tare(tare)
    ref = _reference_wrench_filter(cfg, tare)
    q_rate = np.concatenate([np.square(cfg.wrench_walk_std), np.square(cfg.bias_walk_std)])
    r = np.diag(np.square(cfg.noise_std))
    np.testing.assert_allclose(wf.bias, ref.x[6:, 0], rtol=1e-9, atol=1e-12)
    for k in range(300):
        n = (5, 0, 3, 1)[k % 4]  # cycles with several, none, or one sample
        true = np.array([0.0, 0.2 * np.sin(k / 30), -0.8 * (k > 50), 0.03, 0.0, 0.0])
        samples = bias + true + rng.normal(size=(n, 6)) * std
        wf.update(samples, CYCLE_S)
        ref.predict(Q=np.diag(q_rate * CYCLE_S))
        if n:
            ref.update(samples.mean(axis=0), R=r / n)
        np.testing.assert_allclose(wf.wrench, ref.x[:6, 0], rtol=1e-7, atol=1e-9)
        np.testing.assert_allclose(wf.bias, ref.x[6:, 0], rtol=1e-7, atol=1e-9)
        np.testing.assert_allclose(wf.wrench_std, np.sqrt(np.diag(ref.P)[:6]), rtol=1e-7)


def _tumbling_pose(t: float, rng: np.random.Generator) -> np.ndarray:
    """A tool pose at time ``t`` that turns about all three axes and drifts, with a
    little position noise (one draw of ``rng``): the motion filters' test input."""
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_rotvec([0.3 * t, 0.1 * np.sin(t), -0.2 * t * t]).as_matrix()
    pose[:3, 3] = [0.05 * t, -0.02 * t + 1e-5 * rng.normal(), 0.1 * np.sin(3 * t)]
    return pose


def test_motion_filter_equals_the_18_state_filterpy_filter() -> None:
    cfg = MotionFilterConfig()
    mf = MotionFilter(cfg, CYCLE_S)
    kf = KalmanFilter(dim_x=18, dim_z=6)
    f1 = np.array([[1.0, CYCLE_S, 0.5 * CYCLE_S**2], [0.0, 1.0, CYCLE_S], [0.0, 0.0, 1.0]])
    kf.F = np.kron(np.eye(6), f1)
    kf.H = np.kron(np.eye(6), np.array([[1.0, 0.0, 0.0]]))
    kf.Q = Q_discrete_white_noise(dim=3, dt=CYCLE_S, var=cfg.accel_walk**2 * CYCLE_S,
                                  block_size=6, order_by_dim=True)
    kf.R = np.diag(np.square([cfg.position_noise_m] * 3 + [cfg.rotation_noise_rad] * 3))
    kf.P = np.eye(18) * 1e-2
    rng = np.random.default_rng(4)
    theta = np.zeros(3)
    r_prev = None
    for k in range(300):
        pose = _tumbling_pose(k * CYCLE_S, rng)
        mf.update(pose)
        r = pose[:3, :3]
        if r_prev is None:
            kf.x = np.zeros((18, 1))
            kf.x[0:18:3, 0] = np.concatenate([pose[:3, 3], theta])
        else:
            theta = theta + r_prev @ Rotation.from_matrix(r_prev.T @ r).as_rotvec()
        r_prev = r.copy()
        kf.predict()
        kf.update(np.concatenate([pose[:3, 3], theta]))
        np.testing.assert_allclose(mf.twist_base, kf.x[1:18:3, 0], rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(mf.accel_base, kf.x[2:18:3, 0], rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(mf.twist_tcf(pose)[:3], pose[:3, :3].T @ kf.x[1:9:3, 0],
                               rtol=1e-6, atol=1e-9)


def test_estimator_removes_the_tool_load_of_the_model() -> None:
    """A tool at rest in different orientations with a sensor bias: the tare finds the
    bias alone (shrunk by the prior, ``n/r / (1/100 + n/r)``), the compensation having
    removed :meth:`ToolLoad.wrench` from every sample."""
    from drivers.base.types import FtSamples, RobotState
    from ffexp.estimation import Estimation, Estimator, ToolLoad

    load = ToolLoad(mass_kg=0.35, com_m=(0.01, -0.02, 0.04))
    bias = np.array([0.3, -0.2, 0.5, 0.01, -0.02, 0.005])
    for seed in range(5):
        r = Rotation.random(random_state=seed).as_matrix()
        pose = np.eye(4)
        pose[:3, :3] = r
        est = Estimator(Estimation(tool_load=load), CYCLE_S, 0.1)
        reading = np.tile(load.wrench(r) + bias, (5, 1))
        for k in range(30):
            ft = FtSamples(time_ns=np.arange(5, dtype=np.int64) * 1_000_000 + k * 5_000_000,
                           seq=np.arange(5), wrench=reading, status=np.zeros(5, np.uint32))
            out = est.update(RobotState(tcp_pose_m=pose), ft, k * 5_000_000, 0)
        assert out.tared
        info = out.tare_samples / np.square(np.asarray(Estimation().wrench.noise_std))
        np.testing.assert_allclose(out.bias, bias * info / (1.0 / 100.0 + info), rtol=0,
                                   atol=1e-10)  # the load: about 3 N, summed 100 times
        np.testing.assert_allclose(out.wrench, 0.0, atol=1e-6)  # the shrinkage's rest


def _array_wrench_filter_step(st: dict[str, np.ndarray], r: np.ndarray, q_f: np.ndarray,
                              q_b: np.ndarray, samples: np.ndarray, dt_s: float) -> None:
    """The wrench filter's update as arrays of six (the form the float form replaced)."""
    st["p_ff"] += q_f * dt_s
    st["p_bb"] += q_b * dt_s
    n = samples.shape[0]
    if not n:
        return
    z = np.add.reduce(samples, axis=0) / n if n > 1 else samples[0]
    p_ff, p_fb, p_bb = st["p_ff"], st["p_fb"], st["p_bb"]
    s = p_ff + 2.0 * p_fb + p_bb + r / n
    k_f = (p_ff + p_fb) / s
    k_b = (p_fb + p_bb) / s
    y = z - st["x_f"] - st["x_b"]
    st["x_f"] += k_f * y
    st["x_b"] += k_b * y
    p_ff -= k_f * k_f * s
    p_fb -= k_f * k_b * s
    p_bb -= k_b * k_b * s


def test_wrench_filter_floats_are_bit_identical_to_the_array_form() -> None:
    cfg = WrenchFilterConfig()
    rng = np.random.default_rng(5)
    tare = rng.normal(scale=0.05, size=(300, 6)) + 0.3
    wf = WrenchFilter(cfg)
    wf.tare(tare)
    r = np.square(np.asarray(cfg.noise_std))
    st = {"x_f": np.zeros(6), "x_b": wf.bias, "p_ff": r.copy(), "p_fb": np.zeros(6),
          "p_bb": 1.0 / (1.0 / 100.0 + 300 / r)}
    q_f = np.square(np.asarray(cfg.wrench_walk_std))
    q_b = np.square(np.asarray(cfg.bias_walk_std))
    for k in range(2000):
        samples = rng.normal(scale=2.0, size=(k % 9, 6)) + np.sin(k / 50)
        wf.update(samples, CYCLE_S)
        _array_wrench_filter_step(st, r, q_f, q_b, samples, CYCLE_S)
        assert wf.wrench.tobytes() == st["x_f"].tobytes(), k
        assert wf.bias.tobytes() == st["x_b"].tobytes(), k
        assert wf.wrench_std.tobytes() == np.sqrt(st["p_ff"]).tobytes(), k


def test_estimator_peaks_are_numpys() -> None:
    """The cycle's peak force and torque have the bits of numpy's
    ``sqrt(max((w[:, :3]**2).sum(axis=1)))`` of the raw samples before the tare and of
    the samples less the bias after it; a NaN among them is the peak."""
    from drivers.base.types import FtSamples, RobotState
    from ffexp.estimation import Estimation, Estimator

    def peaks(w: np.ndarray) -> tuple[float, float]:
        sq = w * w
        return (float(np.sqrt(sq[:, :3].sum(axis=1).max())),
                float(np.sqrt(sq[:, 3:].sum(axis=1).max())))

    rng = np.random.default_rng(9)
    est = Estimator(Estimation(), CYCLE_S, 0.05)
    for k in range(600):
        w = rng.normal(size=(1 + k % 12, 6)) * rng.uniform(0.01, 200.0)
        if k == 599:
            w[0, 4] = np.nan
        n = w.shape[0]
        ft = FtSamples(time_ns=np.arange(n, dtype=np.int64) * 400_000 + k * 5_000_000,
                       seq=np.arange(n), wrench=w, status=np.zeros(n, np.uint32))
        tared = est.out.tared
        bias = est.out.bias.copy()
        out = est.update(RobotState(), ft, k * 5_000_000, 0)
        want = peaks(w - bias if tared else w)
        if k == 599:
            assert out.peak_force_n == want[0] and math.isnan(out.peak_torque_nm)
        else:
            assert (out.peak_force_n, out.peak_torque_nm) == want, k
    assert est.out.tared


def test_motion_filter_repeated_gains_are_bit_identical_to_computing_them(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Once its covariance repeats, the filter takes gain and covariance from the cycle
    they repeat in: over a run of varied poses, every state and covariance has the bits
    of the filter that computes them every cycle."""
    import ffexp.estimation.motion_filter as estimation

    cfg = MotionFilterConfig()
    cached = MotionFilter(cfg, CYCLE_S)
    monkeypatch.setattr(estimation, "_GAIN_WATCH_CYCLES", 0)  # never looks: computes
    full = MotionFilter(cfg, CYCLE_S)
    rng = np.random.default_rng(7)
    for k in range(1500):
        pose = _tumbling_pose(k * CYCLE_S, rng)
        cached.update(pose)
        full.update(pose)
        assert np.array_equal(cached._x, full._x)
        assert np.array_equal(cached._p, full._p)
    assert full.gain_period == 0
    assert 0 < cached.gain_period < 1500  # it found the cycle (57 at 5 ms) and used it


def test_contact_detector_signal_is_numpys_norm() -> None:
    """The force-norm signal has the bits of ``np.linalg.norm`` of the force."""
    from ffexp.estimation import ContactDetector, ContactDetectorConfig

    det = ContactDetector(ContactDetectorConfig())
    rng = np.random.default_rng(3)
    for w in rng.normal(size=(2000, 6)) * rng.choice([1e-4, 1.0, 1e3], size=(2000, 1)):
        assert det.signal(w) == float(np.linalg.norm(w[:3]))
