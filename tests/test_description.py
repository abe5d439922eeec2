"""The rig's neutral description (drivers/description): its arm model and that it needs no
simulator."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from drivers.description import LWR4, Scene, compute_layout, seat_depth, tool_tip_offset
from drivers.description.arm import ArmDescription, dh_chain, rpy_matrix


def test_an_arm_description_with_a_missing_joint_value_is_refused() -> None:
    fields = dataclasses.asdict(LWR4)
    fields["link_masses_kg"] = fields["link_masses_kg"][:6]
    with pytest.raises(ValueError, match="link_masses_kg has 6 entries for 7 joints"):
        ArmDescription(**fields)


def test_an_arm_description_with_a_skew_axis_is_refused() -> None:
    fields = dataclasses.asdict(LWR4)
    fields["joint_axes"] = ((1, 1, 0), *fields["joint_axes"][1:])
    with pytest.raises(ValueError, match=r"joint axis \(1, 1, 0\)"):
        ArmDescription(**fields)


def test_the_lwr4_chain_reaches_its_published_length() -> None:
    """Stretched out (all joints 0) the flange is the sum of the published offsets above
    the base: 1.1785 m (0.11 + 0.2005 + 0.20 + 0.20 + 0.20 + 0.19 + 0.078)."""
    assert LWR4.joints == 7
    assert sum(o[2] for o in LWR4.joint_origins_m) == pytest.approx(1.1785)
    assert all(o[:2] == (0.0, 0.0) for o in LWR4.joint_origins_m)


def test_the_layout_puts_the_mouth_where_the_scene_says() -> None:
    """From a start TCF looking along world +x with TCF Y along world -y (the paper pose),
    the funnel mouth is ``distance`` ahead and ``lateral`` along TCF Y, at the TCP's height."""
    scene = Scene()
    tcp = np.array([0.65, 0.0, 0.5])
    rot = np.array([[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]])
    lay = compute_layout(scene, tcp, rot)
    c, s = np.cos(lay.target_yaw), np.sin(lay.target_yaw)
    mouth = lay.target_pos + np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ lay.funnel_in_target
    tg = scene.target
    np.testing.assert_allclose(mouth, [0.65 + tg.distance, -tg.lateral, 0.5], atol=1e-12)
    assert lay.target_yaw == pytest.approx(np.radians(tg.yaw_deg))
    assert 0.0 < lay.funnel_seat_depth == seat_depth(scene) <= tg.funnel.depth
    assert tool_tip_offset(scene) == scene.tool.shaft_length + scene.tool.funnel.depth


def test_the_description_loads_without_the_simulator() -> None:
    code = ("import sys, drivers.description, drivers.vision; "
            "bad = sorted(m for m in sys.modules if m == 'mujoco'"
            " or m.startswith(('drivers.world', 'drivers.sim', 'drivers.emulate')));"
            " print(bad); sys.exit(1 if bad else 0)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120, cwd=Path(__file__).resolve().parents[1])
    assert done.returncode == 0, done.stdout + done.stderr


def test_the_lwr4_description_moves_like_the_3d_view_draws_it() -> None:
    from ffexp.scene3d.kinematics import link_transforms

    rng = np.random.default_rng(3)
    for _ in range(5):
        q = rng.uniform(-2.0, 2.0, LWR4.joints)
        for mine, drawn in zip(LWR4.joint_transforms(q), link_transforms(q), strict=True):
            np.testing.assert_allclose(mine, drawn, atol=1e-15)


def test_rpy_is_the_urdf_fixed_axis_convention() -> None:
    from scipy.spatial.transform import Rotation

    rpy = (0.3, -0.7, 1.9)
    np.testing.assert_allclose(rpy_matrix(rpy), Rotation.from_euler("xyz", rpy).as_matrix(),
                               atol=1e-14)


def _dh(theta: float, a: float, d: float, alpha: float) -> np.ndarray:
    ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    return np.array([[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st],
                     [0.0, sa, ca, d], [0.0, 0.0, 0.0, 1.0]])


def test_a_dh_arm_written_as_a_description_reaches_the_dh_flange() -> None:
    """A six-joint arm given by standard DH parameters (UR-like numbers): the description's
    flange equals the product of the DH link transforms."""
    a = (0.0, -0.425, -0.39, 0.0, 0.0, 0.0)
    d = (0.16, 0.0, 0.0, 0.13, 0.10, 0.10)
    alpha = (np.pi / 2, 0.0, 0.0, np.pi / 2, -np.pi / 2, 0.0)
    chain = dh_chain(a, d, alpha)
    arm = ArmDescription(
        name="six", joint_origins_m=chain.joint_origins_m, joint_axes=((0, 0, 1),) * 6,
        position_limits_deg=(360.0,) * 6, velocity_limits_degps=(180.0,) * 6,
        link_masses_kg=(1.0,) * 6, link_coms_m=((0.0, 0.0, 0.0),) * 6,
        link_inertias_kgm2=((0.01, 0.01, 0.01),) * 6, joint_rpy_rad=chain.joint_rpy_rad,
        flange_m=chain.flange_m, flange_rpy_rad=chain.flange_rpy_rad,
    )
    rng = np.random.default_rng(5)
    for _ in range(5):
        q = rng.uniform(-np.pi, np.pi, 6)
        want = np.eye(4)
        for i in range(6):
            want = want @ _dh(q[i], a[i], d[i], alpha[i])
        np.testing.assert_allclose(arm.flange_pose(q), want, atol=1e-12)
    with pytest.raises(ValueError, match="6 joint positions"):
        LWR4.flange_pose(np.zeros(6))
