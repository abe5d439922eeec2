"""The world's compiled arithmetic (drivers/world/kernels.py) against the numpy form it
replaces, bit for bit, on random inputs (a recording must not change by one ulp)."""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np
import pytest

from drivers.base.types import FtSamples
from drivers.description.scene import FtSensorSettings
from drivers.world.ftsensor import FtSensorModel


def _bits(a: Any) -> bytes:
    return np.ascontiguousarray(a).tobytes()


def _reference(model: FtSensorModel) -> None:
    """Make ``model`` compute its blocks with its numpy form (``_delayed``, ``_block``)
    where it would call the compiled block."""

    def block(white: Any, i: int, raw: Any, buf: Any, dn: int, drift: Any, at: int,
              consts: Any, tared: bool, out: Any, row_over: Any) -> int:
        n = raw.shape[0]
        x = model._delayed(raw) if dn else raw  # the same buffer, shifted the same way
        w, status = model._block(white[i:i + n], x, drift[at:at + n])
        out[:] = w
        row_over[:] = status != 0
        return int(np.count_nonzero(status))

    model._ft_block = block  # type: ignore[method-assign]


def _pair(seed: int, settings: FtSensorSettings, r: Any) -> tuple[FtSensorModel, FtSensorModel]:
    fast = FtSensorModel(settings, np.random.default_rng(seed), r)
    ref = FtSensorModel(settings, np.random.default_rng(seed), r)
    _reference(ref)
    return fast, ref


def _same(a: FtSamples, b: FtSamples) -> None:
    assert _bits(a.wrench) == _bits(b.wrench)
    assert _bits(a.status) == _bits(b.status)
    assert _bits(a.time_ns) == _bits(b.time_ns)
    assert _bits(a.seq) == _bits(b.seq)


#: a resolution so fine that the counts' rounding keeps every bit (2**-60: a value
#: times 2**60 is an integer already), so a product summed otherwise would show
FINE = 2.0**-60


@pytest.mark.parametrize(("delay_s", "resolution"),
                         [(0.0, FINE), (0.001, FINE), (0.003, FINE), (0.001, None)])
def test_ft_block_is_the_numpy_form(delay_s: float, resolution: float | None) -> None:
    """Blocks of changing sizes (one row: numpy's own path), loads far beyond the gauge
    range now and then (the clip and the status), a tare, a replaced bias, a random tool
    offset (the transform's products): every sample and the model's state the same."""
    rng = np.random.default_rng(7)
    for trial in range(6):
        settings = FtSensorSettings(delay_s=delay_s) if resolution is None else \
            FtSensorSettings(delay_s=delay_s, resolution=(resolution, resolution))
        r = rng.normal(size=3) * 0.1 if trial else np.array([0.0, 0.0, -0.12])
        fast, ref = _pair(trial, settings, r)
        t_ns = 0
        for block in range(300):
            n = int(rng.choice([5, 5, 5, 1, 2, 3, 8, 13]))
            raw = rng.normal(size=(n, 6)) * np.array([20.0, 20.0, 40.0, 1.0, 1.0, 1.0])
            if block % 17 == 3:  # some values saturate the gauges
                raw[rng.integers(n), rng.integers(6)] = 1e3 * rng.choice([-1.0, 1.0])
            if block == 100:  # a software tare
                fast.tare_offset = fast.tare_offset + fast.last_wrench
                ref.tare_offset = ref.tare_offset + ref.last_wrench
            if block == 200:  # a new bias object
                fast.bias = fast.bias + 0.25
                ref.bias = ref.bias + 0.25
            _same(fast.process(raw, t_ns), ref.process(raw.copy(), t_ns))
            t_ns += n * fast.period_ns
        assert _bits(fast.drift) == _bits(ref.drift)
        assert _bits(fast.last_wrench) == _bits(ref.last_wrench)
        assert fast.seq == ref.seq


def test_ft_block_saturates_and_flags_rows() -> None:
    """A reading beyond the range comes out clipped to it (then rounded) with the
    saturation bit on its row only."""
    settings = FtSensorSettings(noise_std=(0.0, 0.0), bias_std=(0.0, 0.0),
                                drift_density=(0.0, 0.0), delay_s=0.0)
    model = FtSensorModel(settings, np.random.default_rng(0), np.zeros(3))
    raw = np.zeros((4, 6))
    raw[2, 1] = -500.0  # parent on child: the wrench on the tool is +500 N
    out = model.process(raw, 0)
    assert out.wrench[2, 1] == settings.range[1]
    assert out.status.tolist() == [0, 0, 0x00020000, 0]
    assert not out.wrench[[0, 1, 3]].any()


def test_tool_wrench_is_the_numpy_form() -> None:
    """The contact wrench moved to the TCP and turned into the TCF: the compiled form
    against the numpy one (plain-float cross product, ``@`` with the rotation)."""
    from drivers.world import kernels

    rng = np.random.default_rng(3)
    for _ in range(3000):
        cfrc = rng.normal(size=6) * 10.0 ** rng.uniform(-3, 2, size=6)
        com, tcp = rng.normal(size=3), rng.normal(size=3)
        q = rng.normal(size=4)
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, q / np.linalg.norm(q))
        rot = rot.reshape(3, 3)
        if rng.random() < 0.2:  # exact zeros (their signs: a sum of zeros is +0.0)
            rot = np.eye(3)[rng.permutation(3)] * rng.choice([-1.0, 1.0], size=3)
            cfrc[rng.integers(6, size=3)] = rng.choice([0.0, -0.0], size=3)
        out = np.empty(6)
        kernels.tool_wrench(cfrc, com, tcp, rot, out)
        cx, cy, cz, fx, fy, fz = cfrc.tolist()
        rx, ry, rz = (com - tcp).tolist()
        torque = np.array(((cx + ry * fz) - rz * fy, (cy + rz * fx) - rx * fz,
                           (cz + rx * fy) - ry * fx))
        want = np.concatenate((cfrc[3:] @ rot, torque @ rot))
        assert _bits(out) == _bits(want)


def test_touches_finds_a_tool_geom_in_any_pair() -> None:
    """Any contact whose pair holds a tool geom (first or second) counts; a flex's
    ``-1`` is no geom."""
    from drivers.world import kernels

    is_tool = np.zeros(10, dtype=bool)
    is_tool[[3, 7]] = True
    rng = np.random.default_rng(5)
    for _ in range(500):
        geom = rng.integers(-1, 10, size=(int(rng.integers(0, 40)), 2)).astype(np.int32)
        want = bool(np.isin(geom, [3, 7]).any())
        assert kernels.touches(geom, is_tool) is want
    strided = np.zeros((5, 8), dtype=np.int32)[:, 2:4]  # MuJoCo's contact.geom: a strided view
    strided[4, 1] = 7
    assert kernels.touches(strided, is_tool)
    assert not kernels.touches(strided[:4], is_tool)


@pytest.mark.parametrize("shape", [2.0, 1.0, 1.5])
def test_friction_level_is_the_numpy_form(shape: float) -> None:
    """The dry level written per cycle (compiled around numpy's own ``exp``) equals
    :meth:`JointFriction.dry_level_nm`, the curve in numpy, for speeds from rest to far
    beyond the Stribeck speed (and the clip at 40 of them); a NaN speed (a diverged
    state: the run has stopped before) gives a NaN, its sign bit aside."""
    from drivers.world.friction import JointFriction

    rng = np.random.default_rng(11)
    n = 7
    fr = JointFriction(static_nm=rng.uniform(0.1, 1.0, n), coulomb_nm=rng.uniform(0.05, 0.1, n),
                       viscous_nmsprad=rng.uniform(0.0, 0.1, n),
                       stribeck_radps=rng.uniform(1e-3, 0.1, n), shape=shape)
    out = np.empty(n)
    for _ in range(2000):
        speed = rng.normal(size=n) * 10.0 ** rng.uniform(-5, 1, size=n)
        speed[rng.integers(n)] = rng.choice([0.0, -0.0, 1e3, np.nan, speed[0]])
        fr.apply_into(speed, out)
        want = fr.dry_level_nm(speed)
        assert np.array_equal(np.isnan(out), np.isnan(want))
        out[np.isnan(out)] = want[np.isnan(want)] = 0.0
        assert _bits(out) == _bits(want)


def test_arm_warnings_are_the_limits_value_by_value() -> None:
    """Each bit when and only when one joint passes its limit (speed and torque by
    magnitude, the torque's at the limit already, the position above or below)."""
    from drivers.world import kernels

    rng = np.random.default_rng(13)
    n = 7
    limits = np.array([rng.uniform(1, 2, n), rng.uniform(1, 2, n), -rng.uniform(1, 2, n),
                       rng.uniform(10, 20, n)])
    bits = np.array([4, 16, 64])
    for _ in range(3000):
        scale = rng.uniform(0.5, 1.2)
        qvel = rng.uniform(-1, 1, n) * limits[0] * scale
        q = rng.uniform(-1, 1, n) * 2.0 * scale
        tau = rng.uniform(-1, 1, n) * limits[3] * scale
        if rng.random() < 0.1:
            tau[rng.integers(n)] = -limits[3, 0] if rng.random() < 0.5 else np.nan
            tau[0] = -limits[3, 0]
        want = ((4 if np.any(np.abs(qvel) > limits[0]) else 0)
                | (16 if np.any(q > limits[1]) or np.any(limits[2] > q) else 0)
                | (64 if np.any(np.abs(tau) >= limits[3]) else 0))
        assert kernels.arm_warnings(qvel, q, tau, limits, bits) == want


def test_mujoco_calls_from_compiled_code_are_the_bindings() -> None:
    """The end state's kinematics and bias forces and the TCP's Jacobian and mass
    matrix, made by MuJoCo's functions called from compiled code, equal what the
    Python bindings' calls (and numpy's ``R^T @ jac``) make, at random arm states."""
    from pathlib import Path

    from drivers.description.scene import load_scene
    from drivers.world import kernels
    from drivers.world.world import SimWorld

    root = Path(__file__).resolve().parents[1]
    w = SimWorld(load_scene(root / "data/scenes/paper.toml"))
    m, d = w.model, w.data
    fns = kernels.mujoco_addresses()
    tcp = w._tcp
    rng = np.random.default_rng(17)
    q0, v0 = d.qpos.copy(), d.qvel.copy()
    for _ in range(50):
        d.qpos[:] = q0 + rng.normal(size=q0.shape) * 0.2
        d.qvel[:] = v0 + rng.normal(size=v0.shape)
        # the bindings
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        mujoco.mj_comVel(m, d)
        mujoco.mj_passive(m, d)
        bias = np.zeros(m.nv)
        mujoco.mj_rne(m, d, 0, bias)
        want_state = [d.xpos.copy(), d.xmat.copy(), d.cdof.copy(), d.cvel.copy(),
                      d.qfrc_gravcomp.copy(), bias]
        jac2 = np.zeros((2, 3, m.nv))
        mujoco.mj_jacSite(m, d, jac2[0], jac2[1], tcp)
        want_jac = np.matmul(d.site_xmat[tcp].reshape(3, 3).T, jac2)
        mujoco.mj_makeM(m, d)
        mujoco.mj_factorM(m, d)
        want_m = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, want_m)
        # compiled, from a spoilt state
        for a in (d.xpos, d.xmat, d.cdof, d.cvel, d.qfrc_gravcomp):
            a[:] = np.nan
        got_bias = np.full(m.nv, np.nan)
        kernels.end_state(fns, m._address, d._address, got_bias)
        got_state = [d.xpos, d.xmat, d.cdof, d.cvel, d.qfrc_gravcomp, got_bias]
        assert [_bits(a) for a in got_state] == [_bits(a) for a in want_state]
        jac2[:] = np.nan
        jfull2 = np.full((2, 3, m.nv), np.nan)
        mfull = np.full((m.nv, m.nv), np.nan)
        kernels.tcf_kinematics(fns, m._address, d._address, tcp, jac2,
                               d.site_xmat[tcp].reshape(3, 3), jfull2, True, mfull)
        assert _bits(jfull2) == _bits(want_jac)
        assert _bits(mfull) == _bits(want_m)
