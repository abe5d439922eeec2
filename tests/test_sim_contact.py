"""Funnel contact geometry (drivers/world/funnels.py, drivers/description/funnel.py): smooth
cones from primitives.

The tool's funnel sits on a free body (no gravity) at a chosen pose in the
target funnel; ``mj_forward`` resolves the contact and we read the total
force on the tool. Mechanisms checked: the tool's sphere stack is its cone
to within ``scallop``; the coaxial tool first touches at the seat depth the
module computes; and the direction of the contact force varies with where
the nose lands in steps no larger than a panel crease, where the earlier
capsule funnels jump by several times that.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from drivers.description.funnel import seat_depth, tool_cone_spheres
from drivers.description.scene import Scene
from drivers.world import funnels

TIP = 0.1  # tool tip distance from the tool body's frame in the generated geoms


def _capsule_scene() -> Scene:
    return Scene.model_validate({
        "tool": {"funnel": {"surface": "capsules", "depth": 0.045, "opening": 0.032,
                            "generators": 8}},
        "target": {"funnel": {"surface": "capsules"}},
    })


def _probe_model(scene: Scene) -> mujoco.MjModel:
    """Target funnel fixed at the origin (axis +x); the tool on a free joint, axis +x."""
    xml = f"""<mujoco><option gravity="0 0 0" timestep="0.001" cone="elliptic"/>
<default><default class="funnel"><geom condim="3" friction="0 0.005 0.0001"
  solref="0.002 1" solimp="0.5 0.5 0.001 0.5 2"/></default></default>
<worldbody>
<body name="target_funnel">{funnels.target_funnel_geoms(scene.target.funnel, "funnel")}</body>
<body name="tool"><freejoint/><inertial pos="0 0 0" mass="1" diaginertia="0.01 0.01 0.01"/>
 <body xyaxes="0 1 0 0 0 1"><body pos="0 0 {-TIP}">
  {funnels.tool_funnel_geoms(scene, TIP, "funnel")}</body></body></body>
</worldbody></mujoco>"""
    return mujoco.MjModel.from_xml_string(xml)


def _force_on_tool(m: mujoco.MjModel, d: mujoco.MjData, tip: tuple[float, float, float]) -> (
        np.ndarray):
    d.qpos[:3] = tip
    d.qpos[3:7] = (1.0, 0.0, 0.0, 0.0)
    d.qvel[:] = 0.0
    mujoco.mj_forward(m, d)
    total = np.zeros(3)
    cf = np.zeros(6)
    tool_body = m.body("tool").id
    for i in range(d.ncon):
        c = d.contact[i]
        if c.efc_address < 0:
            continue
        mujoco.mj_contactForce(m, d, i, cf)
        world = cf[:3] @ c.frame.reshape(3, 3)  # force of geom1 on geom2, world frame
        on_tool_is_geom2 = m.body_rootid[m.geom_bodyid[c.geom[1]]] == tool_body
        total += world if on_tool_is_geom2 else -world
    return total


def _first_touch_x(m: mujoco.MjModel, d: mujoco.MjData, dy: float, dz: float) -> float:
    lo, hi = 0.0, 0.07
    for _ in range(32):
        mid = 0.5 * (lo + hi)
        if np.linalg.norm(_force_on_tool(m, d, (mid, dy, dz))) > 0.0:
            hi = mid
        else:
            lo = mid
    return hi


def _normals_around(scene: Scene, depth_m: float, azimuths: np.ndarray) -> np.ndarray:
    """Unit contact force on the tool when its nose presses the wall at each azimuth."""
    m = _probe_model(scene)
    d = mujoco.MjData(m)
    th = scene.target.funnel.half_angle
    out = []
    for phi in azimuths:
        e = np.array([math.cos(phi), math.sin(phi)])
        # the nose centre on the offset cone at this depth, pushed 0.3 mm into the wall
        r_wall = scene.target.funnel.opening - depth_m * math.tan(th)
        r_centre = r_wall - scene.tool.nose_radius / math.cos(th) + 0.0003
        tip_x = depth_m + scene.tool.nose_radius
        f = _force_on_tool(m, d, (tip_x, r_centre * e[0], r_centre * e[1]))
        assert np.linalg.norm(f) > 0.0, f"no contact at azimuth {math.degrees(phi):.1f} deg"
        out.append(f / np.linalg.norm(f))
    return np.array(out)


def test_sphere_stack_is_the_cone_within_the_scallop() -> None:
    scene = Scene()
    f = scene.tool.funnel
    th = f.half_angle
    r_n = scene.tool.nose_radius
    a_apex = r_n - r_n / math.sin(th)
    spheres = tool_cone_spheres(scene)
    # the profile of the stack, along the generator, against the cone line
    s_first = spheres[0][1] / math.tan(th)  # tangency of the nose, distance from the apex
    s_last = spheres[-1][1] / math.tan(th)
    worst_dip = 0.0
    for s in np.linspace(s_first, s_last, 4000):
        # point on the cone's generator at distance s from the apex, in (axial, radial)
        p = np.array([a_apex + s * math.cos(th), s * math.sin(th)])
        outward = np.array([-math.sin(th), math.cos(th)])
        # the stack's surface along the outward normal through p
        reach = max(
            float(np.dot(np.array([a, 0.0]) - p, outward)
                  + math.sqrt(max(rho**2 - float(np.sum((np.array([a, 0.0]) - p) ** 2))
                                  + float(np.dot(np.array([a, 0.0]) - p, outward)) ** 2, 0.0)))
            for a, rho in spheres
        )
        worst_dip = max(worst_dip, -reach)
        assert reach <= 1e-9, "a sphere pokes outside the tool's cone"
    assert worst_dip <= f.scallop * 1.05
    assert worst_dip > 0.0  # the stack is scalloped, not a mislabelled cone


def test_coaxial_tool_first_touches_at_the_seat_depth() -> None:
    scene = Scene()
    m = _probe_model(scene)
    d = mujoco.MjData(m)
    x = _first_touch_x(m, d, 0.0, 0.0)
    # contact is reported within the solver's margin (0 here): bisection to 0.1 um
    assert x == pytest.approx(seat_depth(scene), abs=2e-5)


def test_contact_direction_is_continuous_over_landing_points() -> None:
    """The nose pressing the wall at 0.25 deg steps of azimuth: the force turns smoothly.

    Smooth funnels: between neighbouring landing points the force turns by at
    most one panel crease (360/panels deg), and over the whole sweep it turns
    monotonically with the azimuth, within half a crease of the true cone's
    normal, with the cone's constant axial share sin(30 deg). Capsule funnels:
    the ridges and grooves between generators turn the force away from the
    cone's normal by several times that.
    """
    az = np.radians(np.arange(0.0, 45.0, 0.25))
    smooth = Scene()
    n = _normals_around(smooth, 0.03, az)
    steps = np.degrees(np.arccos(np.clip(np.sum(n[1:] * n[:-1], axis=1), -1.0, 1.0)))
    crease = 360.0 / smooth.target.funnel.panels
    assert steps.max() <= crease * 1.05
    # the wall pushes the nose toward the axis: the force points opposite the landing point
    azimuth_of_force = np.unwrap(np.arctan2(-n[:, 2], -n[:, 1]))
    assert np.all(np.diff(azimuth_of_force) >= -1e-6)  # never turns back (beyond rounding)
    # and it follows the landing point within half a crease
    assert np.max(np.abs(np.degrees(azimuth_of_force - az))) <= crease / 2 + 0.5
    axial = math.sin(smooth.target.funnel.half_angle)
    assert np.allclose(n[:, 0], -axial, atol=0.01)  # the wall pushes the tool back out (-x)

    faceted = _capsule_scene()
    nc = _normals_around(faceted, 0.03, az)
    deviation_c = np.degrees(np.unwrap(np.arctan2(-nc[:, 2], -nc[:, 1])) - az)
    assert np.max(np.abs(deviation_c)) > 3.0 * crease / 2


def test_far_apart_shortcut_equals_the_contact_list() -> None:
    # ToolContact skips the contact list while the tool is beyond the bounding
    # spheres of all it can touch: the same wrench and touching flag as without
    from pathlib import Path

    from drivers.description import load_scene
    from drivers.world import ArmCommand, SimWorld

    scene = load_scene(Path(__file__).resolve().parent.parent / "data" / "scenes" / "paper.toml",
                       ["target.distance=0.1"])
    fast, plain = SimWorld(scene, seed=2), SimWorld(scene, seed=2)
    assert fast._tool_contact._apart is not None
    plain._tool_contact._apart = None
    pose = fast.last_state.tcp_pose_m.copy()
    pose[:3, 3] += 0.15 * pose[:3, 2]
    cmd = ArmCommand(cart_pose_m=pose, tcp_wrench_n_nm=np.array([0.0, 0.0, 2.0, 0, 0, 0]))
    skipped = touching = 0
    for i in range(400):
        fast.advance(cmd if i == 0 else None)
        plain.advance(cmd if i == 0 else None)
        assert fast._touching == plain._touching
        assert fast._contact.tobytes() == plain._contact.tobytes()
        touching += fast._touching
        tx = fast.data.xpos[fast._tool_body]
        skipped += all(float(np.sum((tx - x) ** 2)) > r2 for x, r2 in fast._tool_contact._apart)
    assert touching > 20 and skipped > 20
