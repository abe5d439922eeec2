"""The Mini45 / Net F/T model in isolation (closed-form checks)."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.base.types import FtStatus
from drivers.description.scene import FtSensorSettings
from drivers.world.ftsensor import FtSensorModel

QUIET = FtSensorSettings(noise_std=(0.0, 0.0), bias_std=(0.0, 0.0), drift_density=(0.0, 0.0),
                         delay_s=0.0)


def _model(settings: FtSensorSettings, seed: int = 1, r: float = 0.0) -> FtSensorModel:
    return FtSensorModel(settings, np.random.default_rng(seed), np.array([0.0, 0.0, -r]))


def test_sign_is_environment_on_tool() -> None:
    # MuJoCo reports the force the parent (sensor) applies to the tool. Pushing
    # the tool +Z against an obstacle, the parent pushes +Z: we must read -Z.
    raw = np.array([[0.0, 0.0, 4.0, 0.0, 0.0, 0.0]])
    w = _model(QUIET).process(raw, 0).wrench[0]
    assert w[2] == pytest.approx(-4.0, abs=1 / 32)


def test_torque_referred_to_tcp() -> None:
    # A lateral force fy on the tool, read at a sensing point 0.1 m behind the TCP
    # (r = (0, 0, -0.1)): torque about the TCP = t_site + r x f.
    raw = np.array([[0.0, -2.0, 0.0, -0.2, 0.0, 0.0]])  # parent-on-child
    w = _model(QUIET, r=0.1).process(raw, 0).wrench[0]
    f = np.array([0.0, 2.0, 0.0])
    t_site = np.array([0.2, 0.0, 0.0])
    expected = t_site + np.cross([0.0, 0.0, -0.1], f)
    np.testing.assert_allclose(w[3:], expected, atol=1 / 752)


def test_quantisation_lattice() -> None:
    m = _model(FtSensorSettings())
    s = m.process(np.zeros((500, 6)), 0)
    f_counts = s.wrench[:, :3] * 16.0
    t_counts = s.wrench[:, 3:] * 752.0
    np.testing.assert_allclose(f_counts, np.rint(f_counts), atol=1e-9)
    np.testing.assert_allclose(t_counts, np.rint(t_counts), atol=1e-6)


def test_white_noise_visible_with_expected_spread() -> None:
    st = FtSensorSettings(bias_std=(0.0, 0.0), drift_density=(0.0, 0.0), noise_std=(0.1, 0.0))
    s = _model(st).process(np.zeros((20000, 6)), 0)
    q = 1 / 16
    # Sheppard: quantised Gaussian variance = sigma^2 + q^2 / 12.
    expected = np.sqrt(0.1**2 + q**2 / 12)
    assert np.std(s.wrench[:, 2]) == pytest.approx(expected, rel=0.05)
    assert np.all(s.wrench[:, 3:] == 0.0)


def test_random_walk_drift_grows_as_sqrt_time() -> None:
    st = FtSensorSettings(bias_std=(0.0, 0.0), noise_std=(0.0, 0.0), drift_density=(0.01, 0.0))
    ends = []
    for seed in range(200):
        m = _model(st, seed=seed)
        m.process(np.zeros((4000, 6)), 0)  # 4 s at 1 kHz
        ends.append(m.drift[0])
    # std after T seconds = density * sqrt(T) = 0.02 N
    assert np.std(ends) == pytest.approx(0.01 * np.sqrt(4.0), rel=0.15)


def test_saturation_clips_and_flags() -> None:
    raw = np.array([[0.0, 0.0, -300.0, 0.0, 0.0, 0.0], [0.0, 0.0, -10.0, 0.0, 0.0, 0.0]])
    s = _model(QUIET).process(raw, 0)
    assert s.status[0] & FtStatus.SATURATION
    assert s.status[1] == 0
    assert s.wrench[0, 2] == pytest.approx(290.0)
    assert s.wrench[1, 2] == pytest.approx(10.0)
    assert int(FtStatus.SATURATION) == 0x00020000


def test_timestamps_and_sequence_continue_across_blocks() -> None:
    m = _model(FtSensorSettings(rate=500.0))
    a = m.process(np.zeros((3, 6)), 1_000_000)
    b = m.process(np.zeros((2, 6)), 1_000_000 + 3 * 2_000_000)
    t = np.concatenate([a.time_ns, b.time_ns])
    assert np.all(np.diff(t) == 2_000_000)
    assert list(np.concatenate([a.seq, b.seq])) == [0, 1, 2, 3, 4]


def test_same_seed_same_samples_other_seed_differs() -> None:
    raw = np.zeros((100, 6))
    a = _model(FtSensorSettings(), seed=7).process(raw, 0).wrench
    b = _model(FtSensorSettings(), seed=7).process(raw, 0).wrench
    c = _model(FtSensorSettings(), seed=8).process(raw, 0).wrench
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


def test_delay_shifts_the_readings_by_whole_samples() -> None:
    """A sample stamped t carries the wrench read delay_s earlier; before the first
    reading the first one is held (the sensor read it before the stream started)."""
    st = QUIET.model_copy(update={"delay_s": 0.003})
    raw = np.zeros((10, 6))
    raw[:, 2] = -np.arange(10.0)  # f_z = 0, 1, 2, ... N on the tool
    m = _model(st)
    first = m.process(raw[:4], 0).wrench[:, 2]
    rest = m.process(raw[4:], 4_000_000).wrench[:, 2]
    got = np.concatenate((first, rest))
    res = st.resolution[0]
    expected = np.round(np.concatenate(([0.0] * 3, np.arange(7.0))) / res) * res
    np.testing.assert_array_equal(got, expected)
