"""Wrench and motion filters, tool-load identification and the contact detector."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from ffexp.estimation import (
    ContactDetector,
    ContactDetectorConfig,
    MotionFilter,
    MotionFilterConfig,
    ToolLoad,
    WrenchFilter,
    WrenchFilterConfig,
    identify_tool_load,
)

CFG = WrenchFilterConfig()
STD = np.asarray(CFG.noise_std)
BIAS = np.array([0.5, -0.3, 1.0, 0.01, 0.02, -0.01])


def tared_filter(rng: np.random.Generator, n: int = 400) -> WrenchFilter:
    wf = WrenchFilter(CFG)
    wf.tare(BIAS + rng.normal(size=(n, 6)) * STD)
    return wf


def test_tare_estimates_bias_to_its_statistical_limit() -> None:
    rng = np.random.default_rng(0)
    n = 400
    wf = tared_filter(rng, n)
    # the mean of n samples has std sigma / sqrt(n); allow 4 sigma
    assert np.all(np.abs(wf.bias - BIAS) < 4.0 * STD / np.sqrt(n))
    np.testing.assert_allclose(wf.wrench, 0.0)


def test_filter_follows_a_contact_step_and_keeps_the_bias() -> None:
    rng = np.random.default_rng(1)
    wf = tared_filter(rng)
    bias0 = wf.bias
    true = np.array([0.0, 0.2, -0.8, 0.03, 0.0, 0.0])
    errors = []
    for _ in range(400):  # 2 s at 200 Hz, 5 samples a cycle
        wf.update(BIAS + true + rng.normal(size=(5, 6)) * STD, 0.005)
        errors.append(wf.wrench - true)
    tail = np.array(errors[100:])
    assert np.all(np.abs(tail.mean(axis=0)) < 0.5 * STD)
    # filtered noise is below the raw per-sample noise
    assert np.all(tail.std(axis=0) < STD)
    # the slow bias state did not absorb the contact wrench
    assert np.all(np.abs(wf.bias - bias0) < 0.05 * np.abs(true) + 0.2 * STD)


def test_missing_samples_only_grow_uncertainty() -> None:
    wf = tared_filter(np.random.default_rng(2))
    s0 = wf.wrench_std
    w0 = wf.wrench
    wf.update(np.empty((0, 6)), 0.005)
    assert np.all(wf.wrench_std > s0)
    np.testing.assert_allclose(wf.wrench, w0)



def test_motion_filter_batch_gives_each_run_its_numbers_alone() -> None:
    """Runs stepped together (one filter with a run axis) get, bit for bit, the states,
    twists and accelerations each gets alone, through the gain's repeating cycle; the
    runs move differently (translation, turning about different axes, one at rest)."""
    runs, cycles = 4, 400
    rng = np.random.default_rng(3)
    velocity = rng.normal(size=(runs, 3)) * 0.05
    axes = Rotation.random(runs, random_state=4).as_rotvec()
    axes[2] = 0.0  # one run does not turn
    start = Rotation.random(runs, random_state=5)
    poses = np.zeros((cycles, runs, 4, 4))
    for k in range(cycles):
        t = k * 0.005
        turn = Rotation.from_rotvec(axes * (0.4 * t + 0.1 * np.sin(7 * t))) * start
        poses[k, :, :3, :3] = turn.as_matrix()
        poses[k, :, :3, 3] = velocity * t + 0.002 * rng.normal(size=(runs, 3))
        poses[k, :, 3, 3] = 1.0
    batch = MotionFilter(MotionFilterConfig(), 0.005, runs=runs)
    alone = [MotionFilter(MotionFilterConfig(), 0.005) for _ in range(runs)]
    for k in range(cycles):
        batch.update_batch(poses[k])
        twists = batch.twist_tcf_batch(poses[k])
        for i, mf in enumerate(alone):
            mf.update(poses[k, i])
            assert twists[i].tobytes() == mf.twist_tcf(poses[k, i]).tobytes(), (k, i)
            assert batch.accel_linear_views[i].tobytes() == mf.accel_linear_view.tobytes()
    assert batch.gain_period > 0  # the repeating gain was reached and used
    for i, mf in enumerate(alone):
        assert batch._x[6 * i:6 * i + 6].tobytes() == mf._x.tobytes()
    with pytest.raises(ValueError, match="at least one run"):
        MotionFilter(MotionFilterConfig(), 0.005, runs=0)

def test_motion_filter_velocity_and_rate() -> None:
    mf = MotionFilter(MotionFilterConfig(), 0.005)
    v = np.array([0.05, -0.02, 0.1])
    omega_x = 0.3  # rad/s about base X
    for k in range(400):
        t = k * 0.005
        pose = np.eye(4)
        pose[:3, :3] = Rotation.from_euler("x", omega_x * t).as_matrix()
        pose[:3, 3] = v * t
        mf.update(pose)
    np.testing.assert_allclose(mf.twist_base[:3], v, rtol=1e-3, atol=1e-5)
    np.testing.assert_allclose(mf.twist_base[3:], [omega_x, 0.0, 0.0], atol=1e-3)
    # in the tool frame a rotation about its own X axis is still about X
    np.testing.assert_allclose(mf.twist_tcf(pose)[3:], [omega_x, 0.0, 0.0], atol=1e-3)
    np.testing.assert_allclose(mf.accel_base[:3], 0.0, atol=1e-3)


def test_tool_load_wrench_by_hand() -> None:
    load = ToolLoad(mass_kg=1.0, com_m=(0.1, 0.0, 0.0))
    w = load.wrench(np.eye(3))
    # weight along -Z; lever 0.1 m along +X: torque (0.1, 0, 0) x (0, 0, -9.81) = (0, 0.981, 0)
    np.testing.assert_allclose(w, [0, 0, -9.81, 0, 0.981, 0], atol=1e-12)


def test_identify_tool_load_recovers_mass_com_and_bias() -> None:
    rng = np.random.default_rng(4)
    truth = ToolLoad(mass_kg=0.35, com_m=(0.01, -0.02, 0.06))
    bias = np.array([0.4, -0.2, 0.9, 0.01, -0.02, 0.005])
    rots = Rotation.random(12, random_state=5).as_matrix()
    wrenches = np.array([truth.wrench(r) + bias for r in rots])
    wrenches += rng.normal(size=wrenches.shape) * np.array([0.02] * 3 + [0.002] * 3)
    fit = identify_tool_load(rots, wrenches)
    assert fit.load.mass_kg == pytest.approx(0.35, abs=0.01)
    np.testing.assert_allclose(fit.load.com_m, truth.com_m, atol=0.01)
    np.testing.assert_allclose(fit.bias, bias, atol=0.02)


def test_identify_tool_load_rejects_poses_about_gravity_only() -> None:
    rots = np.array([Rotation.from_euler("z", a).as_matrix() for a in (0.0, 1.0, 2.0, 3.0)])
    with pytest.raises(ValueError, match="orientations"):
        identify_tool_load(rots, np.zeros((4, 6)))


def fz(f: float) -> np.ndarray:
    return np.array([0.0, 0.0, -f, 0.0, 0.0, 0.0])


def test_contact_detector_hysteresis_and_debounce() -> None:
    cfg = ContactDetectorConfig(
        signal="fz", on_threshold_n=0.3, off_threshold_n=0.1, debounce_on_s=0.01,
        debounce_off_s=0.02,
    )
    det = ContactDetector(cfg)
    ms = 1_000_000
    signal = [0.0] * 10 + [0.5] * 1 + [0.0] * 10  # a 1 ms spike: debounced away
    signal += [0.5] * 30  # real contact, starts at t = 21 ms
    signal += [0.2] * 40  # between thresholds: stays in contact
    signal += [0.05] * 10  # a 10 ms dip: shorter than debounce_off
    signal += [0.2] * 10
    signal += [0.0] * 50  # contact lost at t = 21 + 30 + 40 + 10 + 10 = 111 ms
    events = [e for i, s in enumerate(signal) if (e := det.update(i * ms, fz(s))) is not None]
    assert [e.kind for e in events] == ["made", "broken"]
    assert events[0].time_ns == 21 * ms
    assert events[0].previous_s == pytest.approx(0.021)
    assert events[1].time_ns == 111 * ms
    assert events[1].previous_s == pytest.approx(0.090)
    assert not det.in_contact


def test_contact_detector_config_needs_hysteresis() -> None:
    with pytest.raises(ValueError, match="below"):
        ContactDetectorConfig(on_threshold_n=0.2, off_threshold_n=0.2)
