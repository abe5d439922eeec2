"""The step's fused compiled calls give what their separate parts give, bit for bit.

The estimator's cycle with the safety checks in one call against the estimator alone
followed by :meth:`SafetyMonitor.check`; the observer's compiled cycle against its float
form; the funnel's watch (placement, wrapped heading, tolerances, observer) against
:func:`truth_placement`, :func:`wrap_angle` and :meth:`Alignment.within`.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from drivers.base.placement import wrap_angle
from drivers.base.types import FtSamples, FtStatus, LinkHealth, RobotState
from ffexp.contracts import Phase
from ffexp.estimation import Estimation, Estimator
from ffexp.observer import ObserverLimits, WrenchObserver, update_floats
from ffexp.safety import Limits, SafetyMonitor
from ffexp.scenarios.funnel import Alignment


def _rotation(rng: np.random.Generator, scale: float) -> np.ndarray:
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    theta = rng.uniform(0.0, scale)
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]],
                  [-axis[1], axis[0], 0.0]])
    return np.eye(3) + np.sin(theta) * k + (1.0 - np.cos(theta)) * (k @ k)


def _bits(a: object) -> bytes:
    return np.asarray(a, dtype=np.float64).tobytes()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_estimate_checked_in_one_call_is_the_estimate_then_the_checks(seed: int) -> None:
    """Random cycles (samples now and then missing, saturated, large; the link now and
    then unhealthy or not commanding; every phase): the fused call's estimate is the
    estimator's bit for bit and its answer is :meth:`SafetyMonitor.check`'s Stop."""
    rng = np.random.default_rng(seed)
    cfg = Estimation()
    limits = Limits(max_force_n=8.0, max_torque_nm=0.6, max_speed_mps=0.05,
                    workspace_m=(0.01, 0.02, 0.03), stale_ft_s=0.012, link_lost_cycles=3)
    ref, fused = Estimator(cfg, 0.005, 0.05), Estimator(cfg, 0.005, 0.05)
    mon_ref, mon_fused = SafetyMonitor(limits), SafetyMonitor(limits, fused.check_rows())
    pose = np.eye(4)
    pose[:3, 3] = [0.4, 0.1, 0.3]
    phases = list(Phase)
    stops = set()
    for cycle in range(600):
        t_ns = cycle * 5_000_000
        n = int(rng.choice([0, 1, 5, 5, 5]))
        times = t_ns + 1_000_000 * np.arange(n, dtype=np.int64) - 4_000_000
        wrench = rng.normal(scale=rng.choice([0.5, 5.0]), size=(n, 6))
        status = np.where(rng.random(n) < 0.02, int(FtStatus.SATURATION), 0).astype(np.uint32)
        ft = FtSamples(times, np.arange(n, dtype=np.int64), wrench, status)
        pose = pose.copy()
        pose[:3, :3] = pose[:3, :3] @ _rotation(rng, 0.01)
        pose[:3, 3] += rng.normal(scale=2e-4, size=3)
        link = LinkHealth(commanding=bool(rng.random() > 0.1), healthy=bool(rng.random() > 0.1),
                          cycle=cycle, cycle_s=0.005)
        state = RobotState(time_ns=t_ns, tcp_pose_m=pose, joint_pos_rad=np.zeros(7), link=link)
        phase = phases[int(rng.integers(len(phases)))]
        if cycle == 100:
            mon_ref.set_origin(pose)
            mon_fused.set_origin(pose)
        est = ref.update(state, ft, t_ns, 0)
        want = mon_ref.check(t_ns, phase, state, est)
        got_est = fused.update(state, ft, t_ns, 0, mon_fused, phase)
        got = mon_fused.stop_for(fused.safety_code, t_ns, state, got_est)
        assert _bits(got_est.floats) == _bits(est.floats)
        assert got_est.ints.tolist() == est.ints.tolist()  # type: ignore[union-attr]
        assert got == want
        assert mon_fused.ints.tolist() == mon_ref.ints.tolist()
        if want is not None:
            stops.add(want.reason)
    assert len(stops) >= 5  # the checks were exercised, not only the quiet path


LIMITS = ObserverLimits(seated_depth_m=0.03, lateral_force_n=0.3, lateral_torque_nm=0.05,
                        wall_force_ratio=0.5, min_force_n=0.3, lateral_speed_mps=0.002,
                        yaw_rate_radps=math.radians(1.0), hold_s=0.05, target_mass_kg=1e4)
_FIELDS = ("label", "last", "quiet_since_ns", "ever_quiet", "loaded_since_ns",
           "first_contact_z", "impulse_ns", "travel_bound_m", "speed_bound_mps", "last_ns")


def test_the_compiled_observer_is_its_float_form() -> None:
    """Every field of the observer's state after each of many random cycles (NaN, signed
    zeros, pushes and pulls, in and out of contact) as the float form leaves it."""
    rng = np.random.default_rng(7)
    obs = WrenchObserver(LIMITS)
    ref: dict[str, object] = {"label": "unverified", "last": (), "quiet_since_ns": None,
                              "ever_quiet": False, "loaded_since_ns": None,
                              "first_contact_z": None, "impulse_ns": 0.0,
                              "travel_bound_m": 0.0, "speed_bound_mps": 0.0, "last_ns": None}
    labels = set()
    z = 0.0
    mode = 0
    for cycle in range(6000):
        t_ns = cycle * 5_000_000
        if cycle % 60 == 0:  # quiet and seated, on a wall, apart behind, noise
            mode = int(rng.integers(4))
        z += {0: 1e-3, 1: 0.0, 2: -5e-4, 3: float(rng.normal(scale=1e-3))}[mode]
        in_contact = mode != 2 and bool(rng.random() > 0.02)
        if in_contact and ref["first_contact_z"] is None:
            ref["first_contact_z"] = z
            obs.contact_made(z)
        scale = [1e-3, 1e-3, 1e-4, 1e-4, 1e-4] if mode == 0 else [1.0, 0.3, 0.04, 0.002, 0.01]
        mean = [1.0, 2.0 if mode == 1 else 0.0, 0.0, 0.0, 0.0]
        f_z, f_y, t_x, v_y, w_x = (float(v) for v in rng.normal(mean, scale))
        if rng.random() < 0.01:  # a NaN poisons the bounds for good: late in the run
            f_z = float(rng.choice([math.nan, -0.0, 0.0] if cycle > 5000 else [-0.0, 0.0]))
        want = update_floats(LIMITS, ref, t_ns, z, in_contact, f_z, f_y, t_x, v_y, w_x)
        got = obs.update(t_ns, z, in_contact, f_z, f_y, t_x, v_y, w_x)
        labels.add(got)
        assert got == want
        for name in _FIELDS:
            a, b = getattr(obs.state, name), ref[name]
            if isinstance(b, float):
                assert _bits(a) == _bits(b), name
            elif isinstance(b, tuple):
                assert _bits(a) == _bits(b), name
            else:
                assert a == b, name
    assert labels == {"aligned", "not aligned", "unverified"}


def test_the_funnel_watch_wraps_and_judges_as_python() -> None:
    """The heading wrapped as :func:`wrap_angle` and the tolerances as
    :meth:`Alignment.within`, from the compiled watch, on random placements."""
    from ffexp.controllers import kernels as k
    from ffexp.estimation import kernels as ek

    assert (ek.OF_FZ, ek.OF_WRENCH + 1, ek.OF_WRENCH + 3, ek.OF_TWIST + 1,
            ek.OF_TWIST + 3, ek.OI_IN_CONTACT) == (24, 1, 3, 19, 21, 1)  # what it reads
    rng = np.random.default_rng(3)
    a = Alignment(lateral_tol_m=0.02, yaw_tol_deg=20.0, min_insertion_m=0.0)
    tol = np.array([a.lateral_tol_m, a.yaw_tol_deg, a.min_insertion_m])
    obs = WrenchObserver(LIMITS)
    geo = np.zeros(k.GEO_SIZE)
    of, oi = np.zeros(ek.OF_SIZE), np.zeros(ek.OI_SIZE, dtype=np.int64)
    within_seen = set()
    for _ in range(3000):
        tool, mouth = np.eye(4), np.eye(4)
        tool[:3, :3] = _rotation(rng, 4.0)
        mouth[:3, :3] = _rotation(rng, 0.5)
        tool[:3, 3] = rng.normal(scale=0.02, size=3)
        mouth[:3, 3] = rng.normal(scale=0.02, size=3)
        assert k.funnel_observe(tool, mouth, tool, np.array([0.0, 0.0, 1.0]), True, 0.0, tol,
                                geo, of, oi, 0, obs.state.floats, obs.state.ints, obs.lims)
        raw = np.zeros(5)
        assert k.funnel_geometry(tool, mouth, tool, np.array([0.0, 0.0, 1.0]), raw)
        x, y, v, heading, _ = raw.tolist()
        from drivers.base.placement import Placement

        p = Placement((x, y, v, wrap_angle(heading)))
        assert _bits(geo[:4]) == _bits(list(p))
        assert (geo[k.GEO_WITHIN] == 1.0) == a.within(p)
        within_seen.add(a.within(p))
    assert within_seen == {True, False}


def test_the_estimates_columns_are_the_kernels() -> None:
    """The single run's estimate reads the kernels' own columns and flags."""
    from ffexp.estimation import estimator as e
    from ffexp.estimation import kernels as ek

    assert (ek.OF_FZ, ek.OF_PEAK_F, ek.OF_PEAK_T) == (24, 25, 26)
    assert (ek.OI_N, ek.OI_SATURATED, ek.OI_TARED, ek.OI_TARED_NOW, ek.OI_TARE_SAMPLES,
            ek.OI_LAST) == (0, 5, 6, 7, 8, 9)
    assert (ek.R_CHECK, ek.R_IN_CONTACT, ek.R_EVENT) == (15, 16, 32)
    assert ek.STOP_WORKSPACE <= ek.R_CHECK
    assert e._NONE_NS == ek.NONE_NS


def test_the_gain_table_stepped_in_the_compiled_call_is_the_filters_gains() -> None:
    """Once the motion filter's gains repeat, a single run's compiled call steps through
    their table itself: its estimate stays, cycle for cycle and bit for bit, that of a
    batch of one (which asks the filter for each cycle's gain) through several turns of
    the table."""
    rng = np.random.default_rng(7)
    cfg = Estimation()
    single, batch = Estimator(cfg, 0.005, 0.05), Estimator(cfg, 0.005, 0.05)
    pose = np.eye(4)
    pose[:3, 3] = [0.4, 0.1, 0.3]
    for cycle in range(500):
        t_ns = cycle * 5_000_000
        n = int(rng.choice([0, 5, 5]))
        times = t_ns + 1_000_000 * np.arange(n, dtype=np.int64) - 4_000_000
        wrench = rng.normal(scale=2.0, size=(n, 6))
        status = np.zeros(n, dtype=np.uint32)
        pose = pose.copy()
        pose[:3, :3] = pose[:3, :3] @ _rotation(rng, 0.01)
        pose[:3, 3] += rng.normal(scale=2e-4, size=3)
        link = LinkHealth(commanding=True, healthy=True, cycle=cycle, cycle_s=0.005)
        state = RobotState(time_ns=t_ns, tcp_pose_m=pose, joint_pos_rad=np.zeros(7), link=link)
        got = single.update(state, FtSamples(times, np.arange(n, dtype=np.int64), wrench,
                                             status), t_ns, 0)
        want = batch.update_batch(pose[None], wrench, times, status,
                                  np.array([0, n], dtype=np.int64), np.array([True]),
                                  np.array([t_ns], dtype=np.int64),
                                  np.array([0], dtype=np.int64))
        assert _bits(got.floats) == _bits(want.floats[0])
        assert got.ints.tolist() == want.ints[0].tolist()  # type: ignore[union-attr]
    period = single.motion_filter.gain_period
    assert 0 < period < 150  # found early enough for the table to turn a few times
