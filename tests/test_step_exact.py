"""The loop's step restructured for speed gives the numbers of its array form, bit for bit.

Each fast path (floats instead of small numpy calls, work done once) is checked on random
inputs against the straightforward array form it replaces, written out here.
"""

from __future__ import annotations

import numpy as np
import pytest

from drivers.base.placement import Placement, placement, placement_at_mouth, wrap_angle
from drivers.base.types import GroundTruth, LinkHealth, RobotState
from ffexp.contracts import Phase, StopReason
from ffexp.controllers.laws import (
    ForceControlConfig,
    ForceController,
    ImpedanceConfig,
    ImpedanceController,
    rotation_log,
)
from ffexp.estimation import Estimate
from ffexp.safety import Limits, SafetyMonitor


def _rotation(rng: np.random.Generator, angle: float | None = None) -> np.ndarray:
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    theta = rng.uniform(0.0, np.pi) if angle is None else angle
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]],
                  [-axis[1], axis[0], 0.0]])
    return np.eye(3) + np.sin(theta) * k + (1.0 - np.cos(theta)) * (k @ k)


def _pose(rng: np.random.Generator, angle: float | None = None) -> np.ndarray:
    p = np.eye(4)
    p[:3, :3] = _rotation(rng, angle)
    p[:3, 3] = rng.normal(scale=0.5, size=3)
    return p


def _rotation_log_arrays(r: np.ndarray) -> np.ndarray:
    """The array form of ``rotation_log``."""
    cos = float(np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0))
    angle = float(np.arccos(cos))
    v = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    if angle < 1e-9:
        out: np.ndarray = 0.5 * v
        return out
    if np.pi - angle < 1e-6:
        b = (r + np.eye(3)) / 2.0
        k = int(np.argmax(np.diag(b)))
        axis = b[:, k] / np.sqrt(max(b[k, k], 1e-300))
        return axis * angle  # type: ignore[no-any-return]
    return v * (angle / (2.0 * np.sin(angle)))  # type: ignore[no-any-return]


def _impedance_arrays(cfg: ImpedanceConfig, start: np.ndarray, pose: np.ndarray,
                      twist: np.ndarray, elapsed_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The approach law's array form: set-point, pose error, clipped wrench."""
    d = np.asarray(cfg.direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    travel = min(cfg.speed_mps * max(elapsed_s, 0.0), cfg.distance_m)
    sp = start.copy()
    sp[:3, 3] += start[:3, :3] @ (d * travel)
    r = pose[:3, :3]
    e = np.concatenate([r.T @ (sp[:3, 3] - pose[:3, 3]),
                        _rotation_log_arrays(r.T @ sp[:3, :3])])
    lim = np.asarray(cfg.output_limit)
    w = np.clip(np.asarray(cfg.stiffness) * e - np.asarray(cfg.damping) * twist, -lim, lim)
    return sp, w


def test_rotation_log_matches_the_array_form() -> None:
    rng = np.random.default_rng(1)
    for angle in [None] * 300 + [0.0, 1e-12, 5e-10, np.pi, np.pi - 1e-7, np.pi - 1e-5]:
        r = _rotation(rng, angle)
        assert rotation_log(r).tobytes() == _rotation_log_arrays(r).tobytes()


@pytest.mark.parametrize("seed", range(4))
def test_impedance_update_matches_the_array_form(seed: int) -> None:
    rng = np.random.default_rng(seed)
    cfg = ImpedanceConfig(stiffness=tuple(rng.uniform(0, 800, 6)),  # type: ignore[arg-type]
                          damping=tuple(rng.uniform(0, 5, 6)),  # type: ignore[arg-type]
                          direction=tuple(rng.normal(size=3)),  # type: ignore[arg-type]
                          speed_mps=0.02, distance_m=0.05)
    law = ImpedanceController(cfg)
    start = _pose(rng)
    law.start(start)
    for i in range(200):
        # poses near the line (small angles) and anywhere (large ones, near pi too)
        pose = start.copy() if i % 2 else _pose(rng, np.pi - 1e-7 if i % 17 == 0 else None)
        if i % 2:
            pose[:3, :3] = pose[:3, :3] @ _rotation(rng, rng.uniform(0, 1e-3))
            pose[:3, 3] += rng.normal(scale=0.01, size=3)
        twist = rng.normal(scale=0.05, size=6)
        elapsed = float(rng.uniform(-0.5, 4.0))
        sp, w = _impedance_arrays(cfg, start, pose, twist, elapsed)
        got = law.update(pose, twist, elapsed)
        assert got.tobytes() == w.tobytes()
        assert law.setpoint.tobytes() == sp.tobytes()
        assert law.setpoint_at(elapsed).tobytes() == sp.tobytes()


def test_placement_matches_the_mouth_position_and_rotation_form() -> None:
    """``placement`` (the 4x4 mouth's views) gives ``placement_at_mouth``'s numbers (its
    row-major copy of the rotation), bit for bit."""
    rng = np.random.default_rng(5)
    for _ in range(2000):
        tcp, mouth = _pose(rng), _pose(rng)
        tcp[:3, 3] *= rng.uniform(1e-3, 10.0)
        assert placement(tcp, mouth) == placement_at_mouth(tcp, mouth[:3, 3],
                                                           mouth[:3, :3].reshape(9))


def test_the_advance_dot_product_is_matmuls() -> None:
    rng = np.random.default_rng(6)
    for _ in range(2000):
        z, p = rng.normal(size=3), _pose(rng)[:3, 3] * rng.uniform(1e-3, 10.0)
        assert float(z.dot(p)) == float(z @ p)


def _workspace_reference(origin: np.ndarray, pose: np.ndarray, widths: list[float]) -> bool:
    offset = origin[:3, :3].T @ (pose[:3, 3] - origin[:3, 3])
    return any(abs(v) > w for v, w in zip(offset.tolist(), widths, strict=True))


@pytest.mark.parametrize("widths", [(0.05, 0.15, 0.35), (1e-12, 2.0, 0.0), (3e3, 1e-3, 40.0)])
def test_workspace_check_decides_as_the_array_form(widths: tuple[float, float, float]) -> None:
    """The compiled workspace check stops exactly the poses the array form stops, on and
    near the box's faces too (poses placed on a face, then nudged by a few ulps)."""
    rng = np.random.default_rng(7)
    mon = SafetyMonitor(Limits(workspace_m=widths))
    origin = _pose(rng)
    mon.set_origin(origin)
    w = list(widths)
    state = RobotState(time_ns=0, tcp_pose_m=origin.copy(), link=LinkHealth())
    for i in range(3000):
        local = rng.uniform(-1.5, 1.5, 3) * np.asarray(w)
        if i % 3 == 0:  # on a face, give or take an ulp or a few
            axis = int(rng.integers(3))
            local[axis] = np.copysign(w[axis], rng.normal())
            local[axis] = np.nextafter(local[axis], rng.normal() * np.inf)
        pose = state.tcp_pose_m
        pose[:3, 3] = origin[:3, 3] + origin[:3, :3] @ local
        for _ in range(int(rng.integers(0, 4))):
            pose[:3, 3] = np.nextafter(pose[:3, 3], rng.normal(size=3) * np.inf)
        stop = mon.check(0, Phase.APPROACH, state, _estimate(0.0))
        assert (stop is not None) == _workspace_reference(origin, pose, w)
        assert stop is None or stop.reason is StopReason.WORKSPACE_LIMIT


def test_speed_check_is_numpys_norm() -> None:
    """The compiled speed is ``sqrt(v . v)`` as numpy's dot product makes it, bit for bit,
    and the limit is crossed where it is crossed on that."""
    from ffexp.controllers.kernels import MOTION_SPEED, safety_motion

    rng = np.random.default_rng(10)
    out = np.zeros(4)
    for _ in range(3000):
        twist = rng.normal(scale=rng.choice([1e-3, 0.1, 10.0]), size=6)
        v = twist[:3]
        speed = float(np.sqrt(v.dot(v)))
        limit = float(speed if rng.random() < 0.3 else rng.uniform(0, 2) * speed)
        got = safety_motion(twist, limit, np.eye(4), np.eye(4), np.ones(3), False, out)
        assert out[0] == speed
        assert (got == MOTION_SPEED) == (speed > limit)


def _estimate(speed: float) -> Estimate:
    est = Estimate()
    est.n_samples, est.last_sample_ns = 4, 0
    est.twist_tcf = np.array([speed, 0.0, 0.0, 0.0, 0.0, 0.0])
    return est


def test_safety_check_reports_the_workspace_and_speed_limits() -> None:
    """The whole check (the float pre-check in it): inside the box nothing, outside
    the workspace stop with numpy's offset, too fast the speed stop."""
    origin = np.eye(4)
    mon = SafetyMonitor(Limits(workspace_m=(0.05, 0.15, 0.35)))
    mon.set_origin(origin)
    state = RobotState(time_ns=0, tcp_pose_m=origin.copy(),
                       link=LinkHealth(commanding=True, healthy=True))
    assert mon.check(0, Phase.APPROACH, state, _estimate(0.0)) is None
    state.tcp_pose_m[1, 3] = 0.15  # on the face: inside
    assert mon.check(0, Phase.ALIGN, state, _estimate(0.0)) is None
    state.tcp_pose_m[1, 3] = np.nextafter(0.15, 1.0)
    stop = mon.check(0, Phase.ALIGN, state, _estimate(0.0))
    assert stop is not None and stop.reason is StopReason.WORKSPACE_LIMIT
    assert "0.15" in stop.message
    stop = mon.check(0, Phase.APPROACH, state, _estimate(0.3))
    assert stop is not None and stop.reason is StopReason.SPEED_LIMIT


def _force_config(rng: np.random.Generator) -> ForceControlConfig:
    sel = rng.random(6) < 0.5
    sel[2] = True
    return ForceControlConfig(
        force_axes=tuple(bool(s) for s in sel),  # type: ignore[arg-type]
        f_ref=tuple(float(v) if s else 0.0 for v, s in  # type: ignore[arg-type]
                    zip(rng.normal(size=6), sel, strict=True)),
        kp=tuple(float(v) if s else 0.0 for v, s in  # type: ignore[arg-type]
                 zip(rng.uniform(0, 2, 6), sel, strict=True)),
        ki=tuple(float(v) if s and v > 0.3 else 0.0 for v, s in  # type: ignore[arg-type]
                 zip(rng.uniform(0, 3, 6), sel, strict=True)),
        k_ri=tuple(0.0 if s else float(v) for v, s in  # type: ignore[arg-type]
                   zip(rng.uniform(0, 1, 6), sel, strict=True)),
        output_limit=tuple(rng.uniform(0.5, 5, 6)),  # type: ignore[arg-type]
        integral_limit=tuple(rng.uniform(0.0, 2, 6)),  # type: ignore[arg-type]
        contact_feedforward=bool(rng.random() < 0.7))


@pytest.mark.parametrize("seed", range(6))
def test_force_law_compiled_matches_its_float_form(seed: int) -> None:
    """Eq. (9) compiled against the same on Python floats, through saturation, the
    integral's clamp and a NaN reading: every term, the integral and the flag."""
    rng = np.random.default_rng(seed)
    cfg = _force_config(rng)
    fast, ref = ForceController(cfg, 0.005), ForceController(cfg, 0.005)
    for i in range(400):
        w = rng.normal(scale=rng.choice([0.1, 2.0, 40.0]), size=6)
        if i == 250:
            w[int(rng.integers(6))] = np.nan
        a, b = fast.update(w), ref.update_floats(w)
        for name in ("p", "i", "ri", "ff", "total"):
            assert getattr(a, name).tobytes() == getattr(b, name).tobytes(), name
        assert a.saturated == b.saturated
        assert fast.integral.tobytes() == ref.integral.tobytes()
        if i == 300:  # a NaN integral stays NaN in both: start again
            fast.reset()
            ref.reset()


def test_funnel_geometry_matches_truth_placement_and_the_advance() -> None:
    """The funnel's compiled geometry: the truth's placement (its own TCP frame or the
    measured pose) and the advance along the start TCF's z, bit for bit."""
    from ffexp.controllers.kernels import funnel_geometry
    from ffexp.scenarios.funnel import MOUTH_SITE, TCP_SITE, truth_placement

    rng = np.random.default_rng(8)
    out = np.zeros(5)
    for i in range(2000):
        measured, mouth, tool = _pose(rng), _pose(rng), _pose(rng)
        z_axis = _pose(rng)[:3, 2].copy()
        sites = {MOUTH_SITE: mouth} if i % 2 else {MOUTH_SITE: mouth, TCP_SITE: tool}
        truth = GroundTruth(sites=sites)
        funnel_geometry(sites.get(TCP_SITE, measured), mouth, measured, z_axis, out)
        x, y, z, heading, along = out.tolist()
        assert Placement((x, y, z, wrap_angle(heading))) == truth_placement(truth, measured)
        assert along == float(z_axis @ measured[:3, 3])


def test_a_nan_takes_the_float_forms() -> None:
    """A NaN in a pose, twist or wrench: the compiled kernels compute nothing and the
    float forms answer (whose NaN comes out is the order of a sum's operands)."""
    rng = np.random.default_rng(9)
    law, ref = ImpedanceController(ImpedanceConfig()), ImpedanceController(ImpedanceConfig())
    start = _pose(rng)
    law.start(start)
    ref.start(start)
    pose, twist = start.copy(), rng.normal(size=6)
    pose[0, 3] = np.nan
    assert law.update(pose, twist, 1.0).tobytes() == ref.update_floats(pose, twist, 1.0).tobytes()
    twist[4] = np.nan
    assert law.update(start, twist, 1.0).tobytes() == \
        ref.update_floats(start, twist, 1.0).tobytes()
    assert law.setpoint.tobytes() == ref.setpoint.tobytes()

    from ffexp.controllers.kernels import funnel_geometry
    out = np.full(5, 7.0)
    assert not funnel_geometry(pose, start, start, np.ones(3), out)
    assert (out == 7.0).all()
