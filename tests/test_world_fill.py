"""The world's compiled per-cycle calls against the step-by-step forms they replace, bit
for bit: the end of a cycle (``kernels.post_step``) and the state's fill
(``state.StateFill``, ``kernels.fill_state``)."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import pytest

from drivers.base.types import BodyTruth
from drivers.description.scene import Scene, load_scene
from drivers.world import kernels
from drivers.world.arm import ArmCommand, ArmMode, ArmWarning
from drivers.world.contact import ToolContact
from drivers.world.truth import ground_truth, pose
from drivers.world.world import INERTIA_REUSE_RAD, SimWorld

SCENES = Path(__file__).resolve().parent.parent / "data" / "scenes"

BALL = """
name = "ball"
[physics]
gravity = 0.0
integrator = "RK4"
[target]
support = "free"
lateral = 0.8
[[objects]]
name = "ball"
shape = "sphere"
size = [0.06, 0.06, 0.06]
mass = 5.0
distance = 0.06
sites = { centre = [0.0, 0.0, 0.0], top = [0.0, 0.0, 0.03] }
"""


def _bits(a: Any) -> bytes:
    return np.ascontiguousarray(a).tobytes()


def _scene(name: str, tmp_path: Path) -> Scene:
    if name == "ball":
        path = tmp_path / "ball.toml"
        path.write_text(BALL)
        return load_scene(path)
    return load_scene(SCENES / f"{name}.toml")


def _press(w: SimWorld) -> ArmCommand:
    """A command that pushes the tool into the funnel ahead of it."""
    p = w.last_state.tcp_pose_m.copy()
    p[:3, 3] += 0.045 * p[:3, 2]
    return ArmCommand(cart_pose_m=p, tcp_wrench_n_nm=np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0]))


def test_post_step_is_the_step_by_step_form() -> None:
    """Contact wrench, end-state dynamics, divergence counters and the inertia's reuse test
    of one compiled call equal ToolContact.wrench, kernels.end_state and the plain tests."""
    w = SimWorld(load_scene(SCENES / "paper.toml"), seed=3)
    cmd = _press(w)
    m = w.model
    fns = kernels.mujoco_addresses()
    touched = 0
    for k in range(400):
        w.advance(cmd)
        if k % 20:
            continue
        mujoco.mj_step(m, w.data)  # contacts and constraint forces of this step
        ref, new = w.data, copy.copy(w.data)
        contact, touching = ToolContact(m, ref, w._tool_body, w._tool_geoms, w._tcp).wrench()
        kernels.end_state(fns, m._address, ref._address, ref.qfrc_bias)
        tc = ToolContact(m, new, w._tool_body, w._tool_geoms, w._tcp)
        got = np.empty(6)
        q_ref = w._inertia_q + np.linspace(-1.5, 1.5, w._n) * INERTIA_REUSE_RAD
        geom = new.contact.geom if new.ncon else np.zeros((0, 2), dtype=np.int32)
        flags = kernels.post_step(fns, m._address, new._address, *tc.kernel_args,
                                  new.qfrc_bias, new.warning.number, new.qpos[w._qa],
                                  INERTIA_REUSE_RAD, geom, got, q_ref)
        assert bool(flags & kernels.POST_TOUCHING) == touching
        assert _bits(got) == _bits(contact)
        for name in ("qfrc_bias", "qfrc_gravcomp", "xpos", "xmat", "cvel", "cdof_dot",
                     "site_xpos", "subtree_com", "cfrc_ext"):
            assert _bits(getattr(new, name)) == _bits(getattr(ref, name)), name
        moved = bool(np.any(np.abs(ref.qpos[w._qa] - q_ref) > INERTIA_REUSE_RAD))
        assert bool(flags & kernels.POST_INERTIA) == moved
        assert not flags & kernels.POST_DIVERGED
        new.warning[mujoco.mjtWarning.mjWARN_BADQVEL].number = 2  # a bad state counted
        flags = kernels.post_step(fns, m._address, new._address, *tc.kernel_args,
                                  new.qfrc_bias, new.warning.number, new.qpos[w._qa],
                                  INERTIA_REUSE_RAD, geom, got, w._qpos_arm.copy())
        assert flags & kernels.POST_DIVERGED and not flags & kernels.POST_INERTIA
        touched += touching
    assert touched >= 5


def _reference(w: SimWorld) -> dict[str, Any]:
    """The state's fields at the world's end state, field by field with numpy and the
    bindings (the forms the fill replaced)."""
    d = w.data
    q = w._qpos_arm.copy()
    tcp = pose(w._tcp_xpos, w._tcp_xmat) if w.chaser is None else \
        w.chaser.in_base(w._tcp_xpos, w._tcp_xmat)
    cart = w.mode == ArmMode.CART_IMPEDANCE
    jac, mass = w.jacobian, w.mass_matrix
    tau_ext = jac.T @ w._contact
    tau_msr = mass @ w._qacc_arm
    tau_msr += w._bias_arm
    tau_msr -= tau_ext
    work = np.zeros(6)
    bodies = {}
    for name, bid in w.bodies.ids.items():
        mujoco.mj_objectVelocity(w.model, d, mujoco.mjtObj.mjOBJ_BODY, bid, work, 0)
        bodies[name] = (pose(d.xpos[bid], d.xmat[bid]), work[[3, 4, 5, 0, 1, 2]])
    sites = {"funnel_mouth": pose(w._mouth_xpos, w._mouth_xmat)}
    if w.chaser is not None:
        sites["tcp"] = pose(w._tcp_xpos, w._tcp_xmat)
    for name, sid in w._object_sites:
        sites[name] = pose(d.site_xpos[sid], d.site_xmat[sid])
    return {
        "jnt_pos_rad": q, "tcp_pose_m": tcp,
        "cmd_jnt_pos_rad": q.copy() if cart else w._jnt_pos.copy(),
        "cmd_cart_pose_m": w._cart_pos.copy() if cart else tcp.copy(),
        "jacobian": jac, "mass_matrix": mass, "ext_jnt_trq_nm": tau_ext, "jnt_trq_nm": tau_msr,
        "ext_wrench_n_nm": w._contact.copy(), "gravity_nm": w._gravcomp_arm.copy(),
        "tcp_twist": jac @ w._qvel_arm, "bodies": bodies, "sites": sites,
        "base_pose": None if w.chaser is None else w.chaser.arm_base_pose(),
    }


@pytest.mark.parametrize("name", ["paper", "free-flying", "ball"])
def test_the_state_fill_is_the_field_by_field_form(name: str, tmp_path: Path) -> None:
    """Every field of a world's state, filled by one compiled call, has the bits of the
    numpy and MuJoCo-bindings form: in Cartesian impedance pressing, then in a joint mode."""
    w = SimWorld(_scene(name, tmp_path), seed=2)
    cmd = _press(w)
    for k in range(120):
        if k == 80:
            cmd = ArmCommand(mode=ArmMode.JOINT_IMPEDANCE, jnt_pos_rad=w.arm_qpos + 0.01,
                             jnt_stiffness_nmprad=np.full(w._n, 300.0))
        w.advance(cmd)
        cmd = ArmCommand() if k >= 80 else cmd
        if k % 10:
            continue
        s = w.last_state
        if k % 20:  # the fill computes the Jacobian and mass matrix itself
            s.resolve()
            ref = _reference(w)
        else:  # the world's kinematics already made (the reference's)
            ref = _reference(w)
            s.resolve()
        for field in ("jnt_pos_rad", "tcp_pose_m", "cmd_jnt_pos_rad", "cmd_cart_pose_m",
                      "jacobian", "mass_matrix", "ext_jnt_trq_nm", "jnt_trq_nm",
                      "ext_wrench_n_nm", "gravity_nm"):
            got = getattr(s, field)
            assert got.shape == ref[field].shape, field
            assert _bits(got) == _bits(ref[field]), field
        t = s.truth
        assert _bits(t.tcp_twist) == _bits(ref["tcp_twist"])
        assert list(t.bodies) == list(ref["bodies"])
        for body, (p, v) in ref["bodies"].items():
            got_body = t.bodies[body]
            assert _bits(got_body.pose) == _bits(p) and _bits(got_body.twist) == _bits(v)
        assert list(t.sites) == list(ref["sites"])
        for site, p in ref["sites"].items():
            assert _bits(t.sites[site]) == _bits(p), site
        assert (t.base_pose is None) == (ref["base_pose"] is None)
        if t.base_pose is not None:
            assert _bits(t.base_pose) == _bits(ref["base_pose"])
        assert t.contact_wrench is w._contact and t.in_contact == w._touching
        made = ground_truth({}, {}, w._contact, False, np.zeros(6), None, w._attached)
        assert list(vars(t)) == list(vars(made)) and t.topic_prefix == made.topic_prefix
        assert t.attached is w._attached
        assert all(list(vars(b)) == list(vars(BodyTruth())) for b in t.bodies.values())
        assert all(isinstance(b.mass_kg, float) and b.mass_kg > 0 for b in t.bodies.values())
        assert isinstance(s.warning, ArmWarning)


def test_a_field_set_before_the_fill_keeps_its_value() -> None:
    w = SimWorld(load_scene(SCENES / "paper.toml"), seed=1)
    w.advance(None)
    s = w.last_state
    mine = np.arange(7.0)
    s.gravity_nm = mine
    assert s.jnt_pos_rad.shape == (7,)  # the fill
    assert s.gravity_nm is mine


@pytest.mark.parametrize("shape", [(6, 7), (6, 13), (7, 7)])
def test_dot_is_numpys_matmul(shape: tuple[int, int]) -> None:
    """``a.dot(b)`` (the fill's products, on views of its buffer) has the bits of ``@`` on
    a matrix of its own (the forms it replaced): ``A x``, and ``A^T w`` as ``w.dot(A)``."""
    rng = np.random.default_rng(7)
    size = shape[0] * shape[1]
    for k in range(3000):
        a = rng.standard_normal(shape) * 10.0 ** rng.integers(-4, 4, shape)
        x = rng.standard_normal(shape[1])
        y = rng.standard_normal(shape[0])
        # in a buffer at any offset (the state's fields are views of one), or its own
        at = k % 9
        view = np.empty(size + 9)[at:at + size].reshape(shape)
        view[...] = a
        assert _bits(view.dot(x)) == _bits(a @ x)
        assert _bits(y.dot(view)) == _bits(a.T @ y)


def test_set_frame_is_the_bindings_mat2quat() -> None:
    """The commanded frame written by one compiled call: the pose's translation and
    ``mju_mat2Quat`` of its rotation, as the bindings give them (a pose in either order)."""
    fns = kernels.mujoco_addresses()
    rng = np.random.default_rng(5)
    pos, quat, work = np.zeros(3), np.zeros(4), np.zeros(9)
    for k in range(300):
        q = rng.standard_normal(4)
        q /= np.linalg.norm(q)
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, q)
        p = np.eye(4)
        p[:3, :3] = rot.reshape(3, 3)
        p[:3, 3] = rng.standard_normal(3)
        if k % 2:
            p = np.asfortranarray(p)
        want = np.zeros(4)
        mujoco.mju_mat2Quat(want, p[:3, :3].ravel())
        kernels.set_frame(fns, p, pos, quat, work)
        assert _bits(quat) == _bits(want) and _bits(pos) == _bits(p[:3, 3])


@pytest.mark.parametrize("name", ["paper", "free-flying"])
def test_inertia_lhs_is_the_bindings_and_numpys_product(name: str, tmp_path: Path) -> None:
    """``J M^-1 J^T`` of one compiled call (the Jacobian and mass matrix made first, or
    only the factorisation, or neither) has the bits of the bindings' ``mj_solveM`` and
    numpy's product; the world's Cartesian inertia is LAPACK's inverse of it."""
    w = SimWorld(_scene(name, tmp_path), seed=4)
    cmd = _press(w)
    m = w.model
    fns = kernels.mujoco_addresses()
    for k in range(60):
        w.advance(cmd)
        if k % 6:
            continue
        ref = copy.copy(w.data)
        jac2, jfull = np.zeros((2, 3, m.nv)), np.zeros((6, m.nv))
        mujoco.mj_jacSite(m, ref, jac2[0], jac2[1], w._tcp)
        rot = ref.site_xmat[w._tcp].reshape(3, 3)
        jfull[:3], jfull[3:] = rot.T @ jac2[0], rot.T @ jac2[1]
        mujoco.mj_makeM(m, ref)
        mujoco.mj_factorM(m, ref)
        x = np.zeros((6, m.nv))
        mujoco.mj_solveM(m, ref, x, jfull)
        want = jfull @ x.T
        mfull = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, ref, mfull)
        # made by the kernel; the Jacobian made before (the factorisation by the kernel);
        # both made before
        for case in range(3):
            new = copy.copy(w.data)
            j2, jf, mf = np.zeros((2, 3, m.nv)), np.zeros((6, m.nv)), np.zeros((m.nv, m.nv))
            if case:
                kernels.tcf_kinematics(fns, m._address, new._address, w._tcp, j2,
                                       new.site_xmat[w._tcp].reshape(3, 3),
                                       jf.reshape(2, 3, m.nv), case == 2, mf)
            a, diag = np.empty((6, 6)), np.empty(w._n)
            kernels.inertia_lhs(fns, m._address, new._address, w._tcp, j2,
                                new.site_xmat[w._tcp].reshape(3, 3), jf.reshape(2, 3, m.nv),
                                case == 0, case != 2, mf, jf, np.zeros((6, m.nv)), a,
                                w._va.start, diag)
            assert _bits(a) == _bits(want), case
            assert _bits(diag) == _bits(mf.diagonal()[w._va]), case  # the mass matrix's
            if case != 1:  # (made here: the end state's; case 1's full matrix is older)
                assert _bits(mf) == _bits(mfull), case
        w._update_inertia()
        assert _bits(w.cart_inertia) == _bits(np.linalg.inv(want))


def test_history_rows_are_the_ring_view_rolled() -> None:
    """The F/T readings copied from MuJoCo's sensor history by one compiled call are the
    strided view of the ring, rolled to its oldest sample, wherever the ring started; a
    ring whose oldest sample is not the cycle's start is refused."""
    w = SimWorld(load_scene(SCENES / "paper.toml"), seed=1)
    steps = w._ft_steps
    assert steps.uses_history
    view, cursor = steps._hist  # type: ignore[misc]
    m, d, n = w.model, w.data, w.substeps
    for extra in range(n + 2):  # the ring started elsewhere: steps outside the cycle
        for _ in range(extra):
            mujoco.mj_step(m, d)
        t_start = d.time
        mujoco.mj_step(m, d, n)
        oldest = (int(d.history[cursor]) + 1) % n
        want = np.roll(view, -oldest, axis=0).reshape(n, 6)
        raw = np.full((n, 6), np.nan)
        assert kernels.history_rows(d.history, steps._fadr, steps._tadr, n, t_start, raw)
        assert _bits(raw) == _bits(want)
        assert not kernels.history_rows(d.history, steps._fadr, steps._tadr, n,
                                        t_start - m.opt.timestep, raw)


def test_same_or_finite_compares_bits() -> None:
    """The pose latch's test: the same bits (a signed zero differs from the other), else
    finite or not."""
    rng = np.random.default_rng(9)
    cur = rng.standard_normal((4, 4))
    assert kernels.same_or_finite(cur.copy(), cur) == 0
    assert kernels.same_or_finite(np.asfortranarray(cur), cur) == 0
    for value, want in ((np.nextafter(cur[1, 2], 9.0), 1), (np.nan, 2), (np.inf, 2)):
        src = cur.copy()
        src[1, 2] = value
        assert kernels.same_or_finite(src, cur) == want
    zero = np.zeros((4, 4))
    neg = zero.copy()
    neg[3, 3] = -0.0
    assert kernels.same_or_finite(neg, zero) == 1 and kernels.same_or_finite(zero, neg) == 1
    assert kernels.same_or_finite(neg.copy(), neg) == 0


def test_torques_is_numpys_in_place_sum() -> None:
    """``tau += bias; tau -= tau_ext`` compiled, as numpy's two in-place operations."""
    rng = np.random.default_rng(11)
    for _ in range(200):
        tau, bias, ext = (rng.standard_normal(7) * 10.0 ** rng.integers(-6, 6, 7)
                          for _ in range(3))
        want = tau.copy()
        want += bias
        want -= ext
        kernels.torques(tau, bias, ext)
        assert _bits(tau) == _bits(want)
