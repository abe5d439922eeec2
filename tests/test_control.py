"""Control laws against the paper's equations in our sign conventions."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError
from scipy.spatial.transform import Rotation

from ffexp.controllers.laws import (
    ForceControlConfig,
    ForceController,
    ImpedanceConfig,
    ImpedanceController,
    pose_error_tcf,
    rotation_log,
)

DT = 0.005


def paper_case(k_xp: float, k_yp: float, f_ref: float, **kw: object) -> ForceControlConfig:
    return ForceControlConfig(
        f_ref=(0, 0, f_ref, 0, 0, 0), k_ri=(0, k_yp, 0, k_xp, 0, 0), **kw  # type: ignore[arg-type]
    )


def test_reduced_case_is_the_papers_equation() -> None:
    """F*_z = k_zp (f_ref - f_z) + k_zi ∫(f_ref - f_z), F*_y = k_yp w_y, T*_x = k_xp w_tx."""
    cfg = paper_case(0.5, 0.2, 0.8)
    ctl = ForceController(cfg, DT)
    rng = np.random.default_rng(1)
    integral = 0.0
    for _ in range(200):
        w = rng.normal(scale=[0.3, 0.5, 0.6, 0.05, 0.05, 0.05])
        f_z = -w[2]
        integral += (0.8 - f_z) * DT
        terms = ctl.update(w)
        expected = np.zeros(6)
        # F*_z plus the eq. (2) feedforward of the measured contact force f_z
        expected[2] = 1.0 * (0.8 - f_z) + 0.07 * integral + f_z
        expected[1] = 0.2 * w[1]
        expected[3] = 0.5 * w[3]
        np.testing.assert_allclose(terms.total, expected, atol=1e-12)
        np.testing.assert_allclose(
            terms.p + terms.i + terms.ri + terms.ff, terms.total, atol=1e-12
        )
        np.testing.assert_allclose(terms.ff, [0, 0, f_z, 0, 0, 0], atol=1e-12)


def test_feedforward_makes_the_steady_command_f_ref() -> None:
    """With eq. (2)'s feedforward, F_cmd = f_ref once f_z = f_ref; without, 0."""
    w = np.array([0.0, 0.3, -0.8, 0.02, 0.0, 0.0])  # pushing with exactly f_ref
    with_ff = ForceController(paper_case(0.5, 0.2, 0.8), DT).update(w)
    assert with_ff.total[2] == pytest.approx(0.8)
    without = ForceController(paper_case(0.5, 0.2, 0.8, contact_feedforward=False), DT)
    assert without.update(w).total[2] == pytest.approx(0.0)
    # the reduction axes never get the feedforward: applied = k * contact
    assert with_ff.total[1] == pytest.approx(0.2 * 0.3)
    assert with_ff.total[3] == pytest.approx(0.5 * 0.02)


def test_force_axis_signs() -> None:
    ctl = ForceController(
        paper_case(0, 0, 0.8, ki=(0, 0, 0, 0, 0, 0), contact_feedforward=False), DT
    )
    # pushing too lightly (f_z = 0.3 N, i.e. w_z = -0.3): push harder along +Z
    assert ctl.update(np.array([0, 0, -0.3, 0, 0, 0.0])).total[2] == pytest.approx(0.5)
    # pushing too hard: back off
    assert ctl.update(np.array([0, 0, -2.0, 0, 0, 0.0])).total[2] == pytest.approx(-1.2)


@pytest.mark.parametrize(("unit", "scale"), [("per_second", 1.0), ("per_sample", 1.0 / DT)])
def test_integral_gain_reading(unit: str, scale: float) -> None:
    cfg = paper_case(
        0, 0, 1.0, kp=(0, 0, 0, 0, 0, 0), ki_unit=unit, integral_limit=(1e9,) * 6
    )
    ctl = ForceController(cfg, DT)
    for _ in range(100):
        terms = ctl.update(np.zeros(6))  # f_z = 0: error 1 N
    assert terms.i[2] == pytest.approx(0.07 * scale * 1.0 * 100 * DT)


def test_anti_windup_recovers_quickly() -> None:
    cfg = paper_case(0, 0, 5.0, output_limit=(20, 20, 2.0, 2, 2, 2), contact_feedforward=False)
    ctl = ForceController(cfg, DT)
    for _ in range(20_000):  # 100 s of a large error: output saturated at 2 N
        terms = ctl.update(np.zeros(6))
    assert terms.total[2] == pytest.approx(2.0)
    assert terms.saturated
    # without anti-windup the integral would be 500 N s; the clamp keeps it small
    assert abs(ctl.integral[2] * 0.07) <= 10.0 + 1e-9
    # error reverses: the output leaves saturation within a few seconds, not minutes
    steps = 0
    while ctl.update(np.array([0, 0, -8.0, 0, 0, 0])).total[2] > 0.0:
        steps += 1
        assert steps < 2000
    assert steps * DT < 10.0


def test_apparent_inertia_reduction_on_a_point_mass() -> None:
    """A free mass m pushed by f with positive feedback k w moves as mass m/(1+k)."""
    for k in (0.2, 1.0):
        ctl = ForceController(paper_case(0.0, k, 0.8), DT)
        m, f_env = 3.0, 1.5
        w = np.array([0.0, f_env, 0.0, 0.0, 0.0, 0.0])  # environment pushes the tool along +Y
        cmd = ctl.update(w).total
        accel = (f_env + cmd[1]) / m
        assert accel == pytest.approx(f_env / (m / (1.0 + k)), rel=1e-12)


@pytest.mark.parametrize(
    ("kwargs", "word"),
    [
        ({"k_ri": (0, 0, 0.5, 0, 0, 0)}, "k_ri[2]"),
        ({"kp": (1, 0, 1, 0, 0, 0)}, "[0]"),
        ({"f_ref": (0, 1, 0.8, 0, 0, 0)}, "[1]"),
    ],
)
def test_gains_only_where_they_act(kwargs: dict[str, object], word: str) -> None:
    with pytest.raises(ValidationError, match=word.replace("[", r"\[")):
        ForceControlConfig.model_validate(kwargs)


def test_impedance_setpoint_line_and_law() -> None:
    cfg = ImpedanceConfig(speed_mps=0.02, distance_m=0.1)
    ctl = ImpedanceController(cfg)
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_euler("y", 90, degrees=True).as_matrix()  # tool Z = base +X
    ctl.start(pose)
    sp = ctl.setpoint_at(2.0)
    np.testing.assert_allclose(sp[:3, 3], [0.04, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(ctl.setpoint_at(100.0)[:3, 3], [0.1, 0.0, 0.0], atol=1e-12)
    # at rest on the start pose after 1 s: the spring pulls along +Z_tcf by K * 0.02 m
    f = ctl.update(pose, np.zeros(6), 1.0)
    np.testing.assert_allclose(f, [0, 0, 500.0 * 0.02, 0, 0, 0], atol=1e-9)
    # damping opposes the TCF twist
    f = ctl.update(ctl.setpoint_at(1.0), np.array([0.1, -0.2, 0.3, 0.0, 0.0, 1.0]), 1.0)
    np.testing.assert_allclose(f, [-0.1, 0.2, -0.3, 0, 0, -1.0], atol=1e-9)


def test_rotation_log_matches_scipy() -> None:
    rng = np.random.default_rng(3)
    for rv in [*rng.normal(size=(50, 3)), np.array([1e-12, 0, 0]), np.array([0, np.pi - 1e-9, 0])]:
        if np.linalg.norm(rv) > np.pi:
            rv = rv / np.linalg.norm(rv) * (np.linalg.norm(rv) % np.pi)
        r = Rotation.from_rotvec(rv).as_matrix()
        got = rotation_log(r)
        np.testing.assert_allclose(Rotation.from_rotvec(got).as_matrix(), r, atol=1e-7)


def test_pose_error_in_tool_frame() -> None:
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_euler("x", 90, degrees=True).as_matrix()
    sp = pose.copy()
    sp[:3, 3] = [0.0, 0.0, 0.1]  # base +Z is tool +Y after +90 deg about X
    sp[:3, :3] = pose[:3, :3] @ Rotation.from_euler("z", 0.2).as_matrix()
    e = pose_error_tcf(pose, sp)
    np.testing.assert_allclose(e, [0.0, 0.1, 0.0, 0.0, 0.0, 0.2], atol=1e-12)


class _ArrayForceController:
    """The array form of eq. (9) (numpy on 6-vectors), the reference of the per-axis
    float form: both must give the very same bits."""

    def __init__(self, config: ForceControlConfig, cycle_s: float) -> None:
        self.cycle_s = cycle_s
        self._w_sel = np.asarray(config.force_axes, dtype=np.float64)
        self._kp = np.asarray(config.kp, dtype=np.float64)
        self._ki = config.ki_per_second(cycle_s)
        self._kri = np.asarray(config.k_ri, dtype=np.float64)
        self._f_ref = np.asarray(config.f_ref, dtype=np.float64)
        self._out_lim = np.asarray(config.output_limit, dtype=np.float64)
        self._int_lim = np.asarray(config.integral_limit, dtype=np.float64)
        self._ff_sel = self._w_sel if config.contact_feedforward else np.zeros(6)
        self._integral = np.zeros(6)

    def update(self, w: np.ndarray) -> tuple[np.ndarray, ...]:
        error = self._w_sel * (self._f_ref + w)
        p = self._kp * error
        ri = self._kri * (1.0 - self._w_sel) * w
        ff = self._ff_sel * -w
        candidate = self._integral + error * self.cycle_s
        i_clamped = np.clip(self._ki * candidate, -self._int_lim, self._int_lim)
        raw = p + i_clamped + ri + ff
        out = np.clip(raw, -self._out_lim, self._out_lim)
        keep = ~((raw != out) & (np.sign(error) == np.sign(raw)))
        self._integral[keep] = candidate[keep]
        nz = self._ki != 0.0
        self._integral[nz] = np.clip(
            self._integral[nz], -self._int_lim[nz] / np.abs(self._ki[nz]),
            self._int_lim[nz] / np.abs(self._ki[nz]))
        i = self._ki * self._integral
        total = np.clip(p + i + ri + ff, -self._out_lim, self._out_lim)
        return p, i, ri, ff, total, np.array(bool(np.any(raw != out)))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_float_form_is_bit_identical_to_the_array_form(seed: int) -> None:
    rng = np.random.default_rng(seed)
    cfg = ForceControlConfig(
        f_ref=(0, 0, 5.0, 0, 0, 0), k_ri=(0, 0.2, 0, 0.5, 0.1, 0),
        kp=(0.0, 0.0, 0.8, 0.0, 0.0, 0.0), ki=(0.0, 0.0, 3.0, 0.0, 0.0, 0.0),
        integral_limit=(0.0, 0.0, 4.0, 0.0, 0.0, 0.0), output_limit=(2.0, 2.0, 6.0, 0.2, 0.2, 0.2))
    ours, ref = ForceController(cfg, DT), _ArrayForceController(cfg, DT)
    for k in range(3000):  # saturating now and then, signed zeros included
        w = rng.normal(scale=[3.0, 8.0, 20.0, 0.5, 0.5, 0.5]) * (k % 7 != 0)
        if k % 11 == 0:
            w = -w
        t = ours.update(w)
        want = ref.update(w)
        got = (t.p, t.i, t.ri, t.ff, t.total, np.array(t.saturated))
        for a, b in zip(got, want, strict=True):
            assert a.tobytes() == b.tobytes(), k


def test_impedance_output_is_bit_identical_to_the_array_form() -> None:
    """``np.clip(K e - B twist, -lim, lim)`` per axis on floats: the same bits."""
    cfg = ImpedanceConfig(stiffness=(300.0, 300.0, 500.0, 20.0, 20.0, 0.0),
                          damping=(40.0, 40.0, 60.0, 2.0, 2.0, 0.0),
                          output_limit=(5.0, 5.0, 10.0, 0.5, 0.5, 0.0))
    ctl = ImpedanceController(cfg)
    rng = np.random.default_rng(4)
    start = np.eye(4)
    ctl.start(start)
    k, b = np.asarray(cfg.stiffness), np.asarray(cfg.damping)
    lim = np.asarray(cfg.output_limit)
    for i in range(2000):
        pose = np.eye(4)
        pose[:3, :3] = Rotation.from_rotvec(rng.normal(scale=0.05, size=3)).as_matrix()
        pose[:3, 3] = rng.normal(scale=0.03, size=3)
        twist = rng.normal(scale=0.1, size=6) * (i % 5 != 0)
        got = ctl.update(pose, twist, i * DT)
        want = np.clip(k * pose_error_tcf(pose, ctl.setpoint) - b * twist, -lim, lim)
        assert got.tobytes() == want.tobytes(), i


def _array_rotation_log(r: np.ndarray) -> np.ndarray:
    """The former numpy-scalar form of :func:`rotation_log`."""
    cos = np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0)
    angle = float(np.arccos(cos))
    v = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    if angle < 1e-9:
        return 0.5 * v
    if np.pi - angle < 1e-6:
        b = (r + np.eye(3)) / 2.0
        k = int(np.argmax(np.diag(b)))
        return b[:, k] / np.sqrt(max(b[k, k], 1e-300)) * angle
    return v * (angle / (2.0 * np.sin(angle)))


def test_rotation_log_is_bit_identical_to_the_array_form() -> None:
    rng = np.random.default_rng(8)
    for k in range(5000):
        scale = (1e-10, 1e-4, 0.3, 3.14159265)[k % 4]
        r = Rotation.from_rotvec(rng.normal(size=3) * scale).as_matrix()
        if k % 7 == 0:
            r = Rotation.from_rotvec(np.pi * np.array([0.0, 0.0, 1.0])).as_matrix()
        assert rotation_log(r).tobytes() == _array_rotation_log(r).tobytes(), k
