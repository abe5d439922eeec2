"""The Franka driver's compiled kinematics (drivers.franka.kernels) and its law's pinv against
the numpy forms they replace, bit for bit, on random joints and tools, the BLAS sums the
kinematics reproduce against numpy's own products, and the law's kept gains against a
fresh law's."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from drivers.base.blas import dot3_n
from drivers.base.types import CartesianCommand
from drivers.description.arm import rpy_matrix
from drivers.description.lwr4 import LWR4
from drivers.franka.kernels import _matmul
from drivers.franka.law import ImpedanceLaw, pinv
from drivers.franka.model import ArmModel

FR3_Q = np.array([0.0967, -0.0187, 0.0939, -1.5915, 1.5617, 3.3322, 1.5819])


def bits(a: np.ndarray) -> list[int]:
    return np.ascontiguousarray(a, dtype=np.float64).view(np.int64).ravel().tolist()


def random_tool(rng: np.random.Generator) -> np.ndarray:
    """A 4x4 tool, column-major as libfranka hands it (state_from_record)."""
    t = np.eye(4)
    t[:3, :3] = rpy_matrix(rng.uniform(-np.pi, np.pi, 3))
    t[:3, 3] = rng.normal(scale=0.2, size=3)
    return np.asfortranarray(t)


def check_model(model: ArmModel, rng: np.random.Generator, trials: int) -> None:
    n = model.n
    for k in range(trials):
        q = rng.uniform(-3.5, 3.5, n)
        if k % 7 == 0:
            q[rng.random(n) < 0.4] = 0.0  # exact zeros: signed zeros in the sums
        tool = random_tool(rng) if k % 2 else np.ascontiguousarray(random_tool(rng))
        jac, tcp = model.jacobian_tcf(q, tool)
        want_jac, want_tcp = model.jacobian_tcf_numpy(q, tool)
        assert bits(jac) == bits(want_jac)
        assert bits(tcp) == bits(want_tcp)


def test_the_compiled_jacobian_is_the_numpy_form_bit_for_bit() -> None:
    check_model(ArmModel(), np.random.default_rng(7), 3000)


def test_on_an_arm_without_fixed_turns_and_with_signed_axes_too() -> None:
    # the LWR4+ (no joint rpy) and a variant of it with axes of either sign about x and y
    check_model(ArmModel(LWR4), np.random.default_rng(8), 500)
    axes = ((1, 0, 0), (0, -1, 0), (0, 0, -1), (-1, 0, 0), (0, 1, 0), (0, 0, 1), (0, -1, 0))
    twisted = replace(LWR4, joint_axes=axes[:LWR4.joints],
                      joint_rpy_rad=tuple((0.3 * i, -0.2, 0.1 * i) for i in range(LWR4.joints)))
    check_model(ArmModel(twisted), np.random.default_rng(9), 500)


def test_a_second_call_for_the_same_state_is_the_same_read_only_answer() -> None:
    model = ArmModel()
    rng = np.random.default_rng(3)
    q, tool = rng.uniform(-2, 2, 7), random_tool(rng)
    jac, tcp = model.jacobian_tcf(q, tool)
    again = model.jacobian_tcf(q.copy(), tool.copy())
    assert again[0] is jac and again[1] is tcp
    assert not jac.flags.writeable
    q[3] += 1e-9  # moved: computed anew
    moved, _ = model.jacobian_tcf(q, tool)
    assert moved is not jac
    assert bits(moved) == bits(model.jacobian_tcf_numpy(q, tool)[0])


def test_the_sums_are_numpys_products() -> None:
    rng = np.random.default_rng(4)
    for _ in range(2000):
        a, b = rng.normal(size=(4, 4)), rng.normal(size=(4, 4))
        out = np.empty((4, 4))
        _matmul(a, np.asfortranarray(b), out)
        assert bits(out) == bits(a @ np.asfortranarray(b))
        r, c = rng.normal(size=(3, 3)), rng.normal(size=(3, 7))
        out = np.empty((3, 7))
        _matmul(np.ascontiguousarray(r.T), c, out)
        assert bits(out) == bits(r.T @ c)
        x = rng.normal(size=3)
        want = a[:3, :3] @ x
        assert bits(np.array([dot3_n(*a[i, :3], *x) for i in range(3)])) == bits(want)


def test_the_laws_pinv_is_numpys_bit_for_bit() -> None:
    rng = np.random.default_rng(5)
    for k in range(500):
        a = rng.normal(size=(7, 6))
        if k % 5 == 0:  # rank-deficient: singular values under the cut-off are zeroed
            a[:, 5] = a[:, 0] * 2.0
        for m in (a, a.T, np.asfortranarray(a)):
            assert bits(pinv(m)) == bits(np.linalg.pinv(m))


def test_a_new_setpoints_gains_take_effect_at_once() -> None:
    # the clipped stiffness and the damping are kept while the set-point's are the same:
    # a changed stiffness or damping ratio gives the torque a fresh law gives
    model = ArmModel()
    rng = np.random.default_rng(6)
    q, dq, tool = FR3_Q.copy(), rng.normal(scale=0.05, size=7), random_tool(rng)
    _jac, tcp = model.jacobian_tcf(q, tool)
    pose = tcp.copy()
    pose[:3, 3] += (0.01, -0.02, 0.005)
    law = ImpedanceLaw(model, stiffness_max=(3000.0, 300.0), nullspace_damping=1.0,
                       nullspace_stiffness=10.0)
    for stiffness, ratio in ((2000.0, 0.7), (2000.0, 0.7), (5000.0, 0.7), (100.0, 0.3)):
        sp = CartesianCommand(pose_m=pose, stiffness_npm_nmprad=np.full(6, stiffness),
                              damping_ratio=np.full(6, ratio), wrench_n_nm=np.zeros(6))
        fresh = ImpedanceLaw(model, stiffness_max=(3000.0, 300.0), nullspace_damping=1.0,
                             nullspace_stiffness=10.0)
        fresh.q_null = law.q_null
        want = fresh.torque(q, dq, tcp, tool, sp)
        law._last_tau = None  # (the rate limit compares with the last torque: not here)
        assert bits(law.torque(q, dq, tcp, tool, sp)) == bits(want)
        assert law.clipped == (stiffness > 300.0)
