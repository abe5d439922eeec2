"""The estimator with a run axis: N runs stepped together give each run, bit for bit,
what it gets stepped alone (a single run is a batch of one), and the compiled cycle's
sums of products are numpy's own (its BLAS's) on this machine."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from drivers.base.types import FtSamples, FtStatus, LinkHealth, RobotState
from ffexp.estimation import (
    ContactDetectorConfig,
    Estimate,
    Estimation,
    Estimator,
    ToolLoad,
    WrenchFilterConfig,
)

CYCLE_S = 0.005
NS = 1_000_000_000


@dataclass
class Run:
    """One run's settings and how its inputs move."""

    config: Estimation
    tare_s: float
    sample_counts: tuple[int, ...]  # per cycle, in turn (0: no samples that cycle)
    spin_radps: tuple[float, float, float]
    contact_n: float  # the contact force pushed in from cycle 80 to 160
    seed: int


RUNS = (
    Run(Estimation(tool_load=ToolLoad(mass_kg=0.25, com_m=(0.0, 0.01, 0.05))), 0.1,
        (5, 5, 4, 6), (0.0, 0.4, 0.0), 2.0, 1),
    Run(Estimation(tool_load=ToolLoad(mass_kg=0.8, com_m=(0.02, -0.01, 0.1)),
                   inertial_compensation=False,
                   contact=ContactDetectorConfig(signal="fz", on_threshold_n=1.0,
                                                 off_threshold_n=0.5, debounce_on_s=0.0)),
        0.05, (3, 0, 7, 0, 0, 5), (0.3, -0.2, 0.5), -1.5, 2),
    Run(Estimation(), 0.2, (1, 2, 0, 9), (0.0, 0.0, 0.0), 0.6, 3),
    Run(Estimation(tool_load=ToolLoad(mass_kg=0.1, gravity_mps2=0.0),
                   wrench=WrenchFilterConfig(noise_std=(0.1, 0.1, 0.2, 0.01, 0.01, 0.01)),
                   contact=ContactDetectorConfig(on_threshold_n=0.8, off_threshold_n=0.2,
                                                 debounce_off_s=0.0)),
        0.0, (0, 0, 0, 12, 1), (-1.5, 2.0, 0.7), 3.0, 4),
)


def _inputs(run: Run, cycles: int) -> list[tuple[RobotState, FtSamples]]:
    """The run's robot states and F/T samples per cycle: a tumbling, drifting tool; a
    sensor with a bias, noise, a contact force for a while, and a saturation bit now and
    then; the link not commanding for the first cycles."""
    rng = np.random.default_rng(run.seed)
    bias = rng.normal(scale=0.3, size=6)
    out = []
    t_ns = 0
    for k in range(cycles):
        t = k * CYCLE_S
        pose = np.eye(4)
        pose[:3, :3] = Rotation.from_rotvec(np.multiply(run.spin_radps, t)).as_matrix()
        pose[:3, 3] = [0.5 + 0.02 * math.sin(3 * t), 0.01 * t, 0.4 + 0.05 * t * t]
        n = run.sample_counts[k % len(run.sample_counts)]
        times = t_ns + np.arange(n, dtype=np.int64) * int(CYCLE_S * NS // max(n, 1))
        wrench = bias + rng.normal(scale=0.05, size=(n, 6))
        if 80 <= k < 160:
            wrench[:, 2] -= run.contact_n
        status = np.where(rng.random(n) < 0.02, int(FtStatus.SATURATION), 0).astype(np.uint32)
        state = RobotState(time_ns=t_ns, tcp_pose_m=pose,
                           link=LinkHealth(commanding=k >= 3))
        out.append((state, FtSamples(time_ns=times + 7 * NS, seq=np.arange(n),
                                     wrench=wrench, status=status)))
        t_ns += round(CYCLE_S * NS)
    return out


def _fields(e: Estimate) -> tuple[object, ...]:
    return (e.wrench.tobytes(), e.wrench_std.tobytes(), e.bias.tobytes(),
            e.twist_tcf.tobytes(), np.float64(e.f_z).tobytes(),
            np.float64(e.peak_force_n).tobytes(), np.float64(e.peak_torque_nm).tobytes(),
            e.n_samples, e.in_contact, e.event, e.tared, e.tared_now, e.tare_samples,
            e.saturated, e.last_sample_ns)


def test_runs_stepped_together_get_their_numbers_alone() -> None:
    """Four runs with different tool loads (inertia on and off, no gravity), tare times
    (none at all among them), contact settings and noise, and different sample counts
    per cycle (zero too), stepped in one batch: every cycle's outputs of each run equal,
    bit for bit, those of the same run stepped alone, and so do its contact events."""
    cycles = 400
    inputs = [_inputs(run, cycles) for run in RUNS]
    alone = []
    for run, seq in zip(RUNS, inputs, strict=True):
        est = Estimator(run.config, CYCLE_S, run.tare_s)
        t0 = 7 * NS
        alone.append([_fields(est.update(s, ft, s.time_ns, t0)) for s, ft in seq])
        alone[-1].append(tuple(est.detector.events))  # type: ignore[arg-type]
    n = len(RUNS)
    batch = Estimator([r.config for r in RUNS], CYCLE_S, [r.tare_s for r in RUNS])
    got: list[list[tuple[object, ...]]] = [[] for _ in RUNS]
    for k in range(cycles):
        cycle = [seq[k] for seq in inputs]
        fts = [ft for _, ft in cycle]
        offsets = np.concatenate([[0], np.cumsum([len(ft) for ft in fts])]).astype(np.int64)
        out = batch.update_batch(
            np.stack([s.tcp_pose_m for s, _ in cycle]),
            np.concatenate([ft.wrench for ft in fts]).reshape(-1, 6),
            np.concatenate([ft.time_ns for ft in fts]),
            np.concatenate([ft.status for ft in fts]),
            offsets,
            np.array([s.link.commanding for s, _ in cycle]),
            np.array([s.time_ns for s, _ in cycle], dtype=np.int64),
            np.full(n, 7 * NS, dtype=np.int64))
        for i in range(n):
            got[i].append(_batch_fields(batch, out.floats[i], out.ints[i], i))
    for i in range(n):
        got[i].append(tuple(batch.detectors[i].events))
    for i in range(n):
        assert got[i][-1], f"run {i} made no contact event: the test does not reach it"
        for k, (want, have) in enumerate(zip(alone[i], got[i], strict=True)):
            assert want == have, (i, k)


def _batch_fields(est: Estimator, f: np.ndarray, ints: np.ndarray, i: int) -> tuple[object, ...]:
    """A batch row as :func:`_fields` of the run's :class:`Estimate`."""
    from ffexp.estimation import kernels as k

    oi = ints.tolist()
    event = None
    if oi[k.OI_EVENT]:
        event = est.detectors[i].events[-1]
    last = oi[k.OI_LAST]
    return (f[k.OF_WRENCH:k.OF_WRENCH + 6].tobytes(), f[k.OF_STD:k.OF_STD + 6].tobytes(),
            f[k.OF_BIAS:k.OF_BIAS + 6].tobytes(), f[k.OF_TWIST:k.OF_TWIST + 6].tobytes(),
            f[k.OF_FZ].tobytes(), f[k.OF_PEAK_F].tobytes(), f[k.OF_PEAK_T].tobytes(),
            oi[k.OI_N], oi[k.OI_IN_CONTACT] == 1, event, oi[k.OI_TARED] == 1,
            oi[k.OI_TARED_NOW] == 1, oi[k.OI_TARE_SAMPLES], oi[k.OI_SATURATED] == 1,
            None if last == k.NONE_NS else last)


def test_a_batch_needs_one_motion_setting_and_a_setting_per_run() -> None:
    from ffexp.estimation import MotionFilterConfig

    with pytest.raises(ValueError, match="motion filter"):
        Estimator([Estimation(), Estimation(motion=MotionFilterConfig(accel_walk=9.0))],
                  CYCLE_S, 0.1)
    with pytest.raises(ValueError, match="one of each per run"):
        Estimator([Estimation(), Estimation()], CYCLE_S, [0.1])
    with pytest.raises(ValueError, match="update_batch"):
        Estimator([Estimation(), Estimation()], CYCLE_S, 0.1).update(
            RobotState(), FtSamples(), 0, 0)


def test_compiled_sums_of_products_are_numpys() -> None:
    """The compiled cycle sums three products as numpy does through its BLAS (numpy's
    wheels' OpenBLAS, FMA kernels): vector times matrix, matrix times vector, matrix times
    matrix, ``dot``, so recordings made with the numpy form replay bit for bit. A numpy
    whose BLAS sums otherwise fails here, rather than unnoticed in a comparison of
    recordings (the compiled form itself gives the same bits on every machine: the test
    below)."""
    from ffexp.estimation import kernels as k

    def bits(values: object) -> list[int]:  # the doubles' bit patterns: -0.0 is not +0.0
        return np.asarray(values, dtype=np.float64).view(np.uint64).tolist()

    rng = np.random.default_rng(11)
    for n in range(3000):
        pose = rng.normal(size=(4, 4)) * rng.choice([1e-3, 1.0, 1e3])
        r = pose[:3, :3]
        g = rng.normal(size=3)
        a = rng.normal(size=(3, 3))
        x = rng.normal(size=(6, 3))
        if n % 10 == 0:  # zeros against signs: every product a signed zero (a sum of zeros)
            g = np.zeros(3) * rng.choice([-1.0, 1.0], size=3)
            r, a = -np.abs(r), -np.abs(a)
            x[:2] = 0.0
        want_vm, want_mv, want_mm = g @ r, a @ g, (x @ a).ravel()
        assert bits([k.dot3(*g, *r[:, j]) for j in range(3)]) == bits(want_vm)
        assert bits([k.dot3_n(*a[i], *g) for i in range(3)]) == bits(want_mv)
        assert bits([k.dot3(*x[i], *a[:, j]) for i in range(6) for j in range(3)]) == \
            bits(want_mm)
        assert bits([k.dot3(*g, *g)]) == bits([g.dot(g)])
        assert bits([k.dot3(*g, *r[:, 0])]) == bits([np.dot(g, r[:, 0])])


def test_compiled_sums_of_products_round_as_documented() -> None:
    """``dot3`` is ``fma(a2, b2, fma(a1, b1, a0 b0))`` and ``dot3_n`` is ``fma(a2, b2,
    fma(a0, b0, a1 b1))`` (each from an accumulator of ``+0.0``), each step rounded once:
    checked against exact rational arithmetic rounded to the nearest double (the same on
    every machine)."""
    from fractions import Fraction

    from ffexp.estimation import kernels as k

    def fma(a: float, b: float, c: float) -> float:
        return float(Fraction(a) * Fraction(b) + Fraction(c))

    rng = np.random.default_rng(12)
    for _ in range(2000):
        a0, a1, a2, b0, b1, b2 = (rng.normal(size=6) * rng.choice([1e-8, 1.0, 1e8], size=6)
                                  ).tolist()
        assert k.dot3(a0, a1, a2, b0, b1, b2) == fma(a2, b2, fma(a1, b1, a0 * b0))
        assert k.dot3_n(a0, a1, a2, b0, b1, b2) == fma(a2, b2, fma(a0, b0, a1 * b1))


def test_the_compiled_gain_step_is_the_numpy_form() -> None:
    """:func:`kernels.motion_gain` (the motion filter's covariance and gain of a cycle)
    against the numpy form it replaces, ``P = F1 P F1^T + Q1``, ``k = P[:, :, 0] /
    (P[:, 0, 0] + r)``, ``P -= k P[0, :]``, on random covariances, cycles and noises, bit
    for bit; and a filter's own sequence against that form cycle after cycle."""
    from ffexp.estimation import kernels as k
    from ffexp.estimation.motion_filter import MotionFilter, MotionFilterConfig

    def numpy_form(mf: MotionFilter, p0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p = mf._f1 @ p0 @ mf._f1_t
        p += mf._q1
        s = p[:, 0, 0] + mf._r
        gain = p[:, :, 0] / s[:, None]
        p -= gain[:, :, None] * p[:, None, 0, :]
        return gain, p

    rng = np.random.default_rng(5)
    for _ in range(1000):
        cfg = MotionFilterConfig(position_noise_m=rng.uniform(1e-6, 1e-3),
                                 rotation_noise_rad=rng.uniform(1e-5, 1e-2),
                                 accel_walk=rng.uniform(1.0, 100.0))
        mf = MotionFilter(cfg, float(rng.choice([0.001, 0.005, rng.uniform(1e-4, 0.02)])))
        m = rng.normal(size=(6, 3, 3))
        p0 = (m @ m.transpose(0, 2, 1)) * rng.uniform(1e-8, 1.0)
        gain, p = np.empty((6, 3)), np.empty((6, 3, 3))
        k.motion_gain(mf._f1, p0, mf._f1_t, mf._q1, mf._r, gain, p)
        want_gain, want_p = numpy_form(mf, p0)
        assert gain.tobytes() == want_gain.tobytes()
        assert p.tobytes() == want_p.tobytes()
    mf = MotionFilter(MotionFilterConfig(), CYCLE_S)
    p = mf._p.copy()
    for _ in range(300):  # through the start and past the gains' repeat
        want_gain, p = numpy_form(mf, p)
        assert mf.next_gain().tobytes() == want_gain.tobytes()
        assert mf._p.tobytes() == p.tobytes()
    assert mf.gain_period > 0
