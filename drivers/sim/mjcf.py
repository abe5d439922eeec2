"""MJCF of the rig, generated from a :class:`~drivers.sim.scene.Scene`.

Written by us from published numbers; no third-party model file is copied.

Sources of the numbers (public; the choices made where they are silent are
listed in ``drivers/sim/NOTES.md``):

* Kinematics (joint offsets 0.11 / 0.2005 / 0.20 / 0.20 / 0.20 / 0.19 /
  0.078 m, axes +z -y +z +y +z -y +z, position limits 170/120 deg,
  velocity limits, effort limits 176/176/100/100/100/38/38 N m):
  CentroEPiaggio/kuka-lwr ``lwr_description/model/kuka_lwr.urdf.xacro``
  (commit 464d48c). Velocity limits: same file.
* Link masses, centres of mass and principal inertias: the AUTh mesh-derived
  set, iSaran/robamine ``rlrl-py/rlrl_py/envs/assets/xml/lwr/lwr_robot.xml``
  ("Source: auth-arl/autharl_core"). The principal-axis orientations of that
  file are not in our fact sheet, so the principal moments are used about the
  link axes (an approximation of second order: the off-diagonal terms).
* Joint friction and reflected rotor inertia: Jubien 2014 identified values
  (ISIR-SYROCO/kukaKDL ``kukakdl_const.hpp``), scaled by settings, because
  those are drive-side and the LWR's torque loop hides most of them.
* ATI Mini45: 45 mm diameter, 15.7 mm height, 0.0917 kg (ATI catalogue).

The TCF (site ``tcp``) is the flange frame turned by 180 deg about the tool
axis and moved to the tool tip: in the paper pose (flange along world +x) TCF
X points up, Y along world -y, Z along world +x. The sensor site ``ft_site``
has the same axes, on the Mini45's tool-side face.

MuJoCo choices (fact sheet sec. 3): ``implicitfast``, elliptic cones,
Newton; the funnels are spheres (tool) against thin boxes (target), a
primitive pair (:mod:`drivers.sim.funnels`); the target moves in the bed
plane on x/y slides and a z hinge at its centre of mass, plus a z slide so
that four sphere pads carry its weight on the glass and bed friction is
isotropic Coulomb friction ``mu * m * g``.
The KRC's Cartesian impedance law is built from MuJoCo actuators so it runs
inside the physics step (see :mod:`drivers.sim.world`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from drivers.sim import funnels
from drivers.sim.scene import Scene

#: Joint-origin offsets along the parent z axis [m] (CentroEPiaggio URDF).
LWR_OFFSETS = (0.11, 0.2005, 0.20, 0.20, 0.20, 0.19, 0.078)
#: Joint axes in the link frame (CentroEPiaggio URDF).
LWR_AXES = ((0, 0, 1), (0, -1, 0), (0, 0, 1), (0, 1, 0), (0, 0, 1), (0, -1, 0), (0, 0, 1))
#: Position limits [deg] (CentroEPiaggio URDF; also KRC rsidef7.dat via TUM kuka_fri).
LWR_POS_LIMITS_DEG = (170.0, 120.0, 170.0, 120.0, 170.0, 120.0, 170.0)
#: Velocity limits [deg/s] (CentroEPiaggio URDF).
LWR_VEL_LIMITS_DEG = (110.0, 110.0, 128.0, 128.0, 204.0, 184.0, 184.0)
#: Link masses [kg], links 1..7 (AUTh mesh-derived set).
LWR_MASSES = (2.59818, 2.61292, 2.59818, 2.61292, 1.94073, 1.27744, 0.0698888)
#: Link centres of mass [m] in the link frame (AUTh set).
LWR_COMS = (
    (0.0, 0.0387, 0.1519),
    (0.0, -0.0371, 0.0615),
    (0.0, -0.0387, 0.1519),
    (0.0, 0.0371, 0.0615),
    (0.0004, 0.0296, 0.1109),
    (0.0, -0.0140, -0.0012),
    (0.0, 0.0, -0.0087),
)
#: Principal inertias [kg m^2] (AUTh set).
LWR_INERTIAS = (
    (0.01432, 0.01406, 0.00483),
    (0.01675, 0.01618, 0.00449),
    (0.01432, 0.01406, 0.00483),
    (0.01675, 0.01618, 0.00449),
    (0.00995, 0.00893, 0.00301),
    (0.00286, 0.00247, 0.00232),
    (4.7e-5, 2.5e-5, 2.5e-5),
)
#: Jubien 2014 reflected rotor inertias [kg m^2] for A3..A7; A1/A2 are not
#: separable from the grouped parameters and are taken equal to A3 (assumption).
JUBIEN_ROTOR = (2.01, 2.01, 2.01, 1.92, 0.776, 0.391, 0.399)

ARM_JOINTS = tuple(f"a{i + 1}" for i in range(7))
TARGET_JOINTS = ("target_x", "target_y", "target_z", "target_yaw")
FT_SENSOR_FORCE = "ft_force"
FT_SENSOR_TORQUE = "ft_torque"

#: Funnel contacts within margin + gap are reported (MuJoCo 4.0 sums the two
#: geoms' values: 0.8 mm for a pair) and the ground truth calls them "in
#: contact", so sliding over the panel creases (or the capsule ridges) is not
#: counted as contact breaks. Only from within the pair's margin (0.4 mm) do they
#: push, with a spring on the distance minus the margin that starts from zero
#: force (measured): the funnels' contact surfaces stand 0.2 mm proud of the geoms.
TOUCH_MARGIN = 2e-4

# Collision groups: tool funnel <-> target funnel, pads <-> glass, nothing else.
_PAD = 'contype="4" conaffinity="8"'
_GLASS = 'contype="8" conaffinity="4"'
_VISUAL = 'contype="0" conaffinity="0"'


@dataclass(frozen=True)
class Layout:
    """Where the scene puts things (world frame), derived from the start TCF."""

    glass_z: float
    target_pos: NDArray[np.float64]
    target_yaw: float
    funnel_in_target: NDArray[np.float64]
    """Mouth centre of the target funnel in the target body frame."""
    funnel_seat_depth: float
    """Insertion depth of the tool tip when the cones are seated [m]."""


def _f(v: float) -> str:
    return f"{v:.9g}"


def _vec(v: object) -> str:
    return " ".join(_f(float(x)) for x in v)  # type: ignore[attr-defined]


def tool_tip_offset(scene: Scene) -> float:
    """Distance from the sensing face of the Mini45 to the TCP (tool tip) [m]."""
    return scene.tool.shaft_length + scene.tool.funnel.depth


def arm_xml(scene: Scene) -> str:
    """The LWR4+ chain with sensor and tool, as nested bodies."""
    arm = scene.arm
    coul = arm.coulomb_friction()
    visc = arm.viscous_friction()
    tip = tool_tip_offset(scene)
    tool = scene.tool
    L = tip
    rr = tool.funnel.opening * 0.6
    i_tool = (
        tool.mass * (3 * rr**2 + L**2) / 12.0,
        tool.mass * (3 * rr**2 + L**2) / 12.0,
        tool.mass * rr**2 / 2.0,
    )
    sensor_i = (
        tool.sensor_mass * (3 * tool.sensor_radius**2 + tool.sensor_height**2) / 12.0,
        tool.sensor_mass * (3 * tool.sensor_radius**2 + tool.sensor_height**2) / 12.0,
        tool.sensor_mass * tool.sensor_radius**2 / 2.0,
    )
    inner = (
        f'<body name="mini45" gravcomp="1">\n'
        f'<inertial pos="0 0 {_f(tool.sensor_height / 2)}" mass="{_f(tool.sensor_mass)}" '
        f'diaginertia="{_vec(sensor_i)}"/>\n'
        f'<geom type="cylinder" size="{_f(tool.sensor_radius)} {_f(tool.sensor_height / 2)}" '
        f'pos="0 0 {_f(tool.sensor_height / 2)}" {_VISUAL} mass="0" rgba="0.2 0.2 0.2 1"/>\n'
        f'<body name="tool" pos="0 0 {_f(tool.sensor_height)}" gravcomp="1">\n'
        f'<inertial pos="0 0 {_f(L / 2)}" mass="{_f(tool.mass)}" diaginertia="{_vec(i_tool)}"/>\n'
        f'<site name="ft_site" pos="0 0 0" quat="0 0 0 1"/>\n'
        f'<site name="tcp" pos="0 0 {_f(tip)}" quat="0 0 0 1"/>\n'
        f'<geom name="tool_body" type="capsule" size="0.012" '
        f'fromto="0 0 0 0 0 {_f(max(tip - tool.funnel.depth, 0.001))}" {_VISUAL} mass="0" '
        f'rgba="0.6 0.6 0.6 1"/>\n'
        f"{funnels.tool_funnel_geoms(scene, tip, 'funnel')}\n"
        f"</body>\n</body>"
    )
    for i in reversed(range(7)):
        lim = math.radians(LWR_POS_LIMITS_DEG[i])
        tl = arm.torque_limits[i]
        arm_len = LWR_OFFSETS[i + 1] if i < 6 else 0.02
        joint = (
            f'<joint name="{ARM_JOINTS[i]}" axis="{_vec(LWR_AXES[i])}" '
            f'range="{_f(-lim)} {_f(lim)}" '
            f'frictionloss="{_f(coul[i])}" damping="{_f(visc[i])}" '
            f'armature="{_f(JUBIEN_ROTOR[i] * arm.armature_scale)}" '
            f'actuatorfrcrange="{_f(-tl)} {_f(tl)}" actuatorgravcomp="true" '
            # stiff friction constraint: creep below breakaway ~20 um/s instead of ~2 mm/s
            f'solreffriction="{_f(max(0.002, 2 * scene.physics.timestep))} 1" '
            f'solimpfriction="0.99 0.999 0.001"/>'
        )
        inner = (
            f'<body name="link{i + 1}" pos="0 0 {_f(LWR_OFFSETS[i])}" gravcomp="1">\n'
            f'<inertial pos="{_vec(LWR_COMS[i])}" mass="{_f(LWR_MASSES[i])}" '
            f'diaginertia="{_vec(LWR_INERTIAS[i])}"/>\n'
            f"{joint}\n"
            f'<geom type="capsule" size="0.06" fromto="0 0 0 0 0 {_f(arm_len)}" {_VISUAL} '
            f'mass="0" rgba="1 0.5 0 0.6"/>\n'
            f"{inner}\n</body>"
        )
    base = _vec(arm.base_pos)
    return (
        f'<body name="link0" pos="{base}">\n'
        f'<geom type="cylinder" size="0.06 0.055" pos="0 0 0.055" {_VISUAL} mass="0"/>\n'
        f"{inner}\n</body>"
    )


def target_xml(scene: Scene, layout: Layout) -> str:
    tg = scene.target
    sx, sy, sz = tg.size
    m = tg.mass
    inertia = (m * (sy**2 + sz**2) / 12.0, m * (sx**2 + sz**2) / 12.0, m * (sx**2 + sy**2) / 12.0)
    pad_r = 0.008
    pads = []
    for k, (px, py) in enumerate(((1, 1), (1, -1), (-1, 1), (-1, -1))):
        pads.append(
            f'<geom name="pad{k}" type="sphere" size="{_f(pad_r)}" '
            f'pos="{_f(px * 0.4 * sx)} {_f(py * 0.4 * sy)} {_f(-sz / 2 + pad_r)}" {_PAD} '
            f'class="pad"/>'
        )
    hose_k = tg.hose.stiffness
    hose_b = tg.hose.damping
    # The body frame is world-aligned so the slides move along world x and y;
    # the start yaw is the hinge's initial angle (set in ``qpos0`` by SimWorld).
    return (
        f'<body name="target" pos="{_vec(layout.target_pos)}">\n'
        f'<inertial pos="0 0 0" mass="{_f(m)}" diaginertia="{_vec(inertia)}"/>\n'
        f'<joint name="target_x" type="slide" axis="1 0 0" stiffness="{_f(hose_k)}" '
        f'damping="{_f(hose_b)}" ref="0"/>\n'
        f'<joint name="target_y" type="slide" axis="0 1 0" stiffness="{_f(hose_k)}" '
        f'damping="{_f(hose_b)}"/>\n'
        f'<joint name="target_z" type="slide" axis="0 0 1"/>\n'
        f'<joint name="target_yaw" type="hinge" axis="0 0 1" pos="0 0 0"/>\n'
        f'<geom type="box" size="{_f(sx / 2)} {_f(sy / 2)} {_f(sz / 2)}" {_VISUAL} mass="0" '
        f'rgba="0.75 0.75 0.8 1"/>\n'
        + "\n".join(pads)
        + f'\n<body name="target_funnel" pos="{_vec(layout.funnel_in_target)}">\n'
        f'<site name="funnel_mouth" pos="0 0 0"/>\n'
        f"{funnels.target_funnel_geoms(tg.funnel, 'funnel')}\n</body>\n</body>"
    )


def funnel_axis_height(scene: Scene) -> float:
    """Height of the target funnel's axis above the glass [m]."""
    f = scene.target.funnel
    return scene.target.size[2] + f.opening + f.capsule_radius + 0.005


def compute_layout(
    scene: Scene, tcp_pos: NDArray[np.float64], tcp_rot: NDArray[np.float64]
) -> Layout:
    """Place glass and target from the start TCF (``tcp_rot`` columns = TCF axes in world)."""
    tg = scene.target
    z_axis = tcp_rot[:, 2].copy()
    y_axis = tcp_rot[:, 1].copy()
    z_axis[2] = 0.0
    y_axis[2] = 0.0
    z_axis /= max(float(np.linalg.norm(z_axis)), 1e-12)
    y_axis /= max(float(np.linalg.norm(y_axis)), 1e-12)
    h = funnel_axis_height(scene)
    glass_z = float(tcp_pos[2]) - h
    mouth = tcp_pos + tg.distance * z_axis + tg.lateral * y_axis
    mouth[2] = tcp_pos[2]
    yaw0 = math.atan2(z_axis[1], z_axis[0])
    yaw = yaw0 + math.radians(tg.yaw_deg)
    funnel_in_target = np.array(
        [-tg.size[0] / 2.0, 0.0, h - tg.size[2] / 2.0], dtype=np.float64
    )
    c, s = math.cos(yaw), math.sin(yaw)
    rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    center = mouth - rz @ funnel_in_target
    return Layout(
        glass_z=glass_z,
        target_pos=center,
        target_yaw=yaw,
        funnel_in_target=funnel_in_target,
        funnel_seat_depth=funnels.seat_depth(scene),
    )


def build_xml(scene: Scene, layout: Layout | None) -> str:
    """The whole model. With ``layout=None`` only the arm (used to find the start TCF)."""
    ph = scene.physics
    ct = scene.contact
    target = "" if layout is None else target_xml(scene, layout)
    glass_z = 0.0 if layout is None else layout.glass_z
    mu = scene.target.mu
    pad_condim = 3 if mu > 0.0 else 1
    cart = "\n".join(
        f'<general name="cart_{ax}" site="tcp" refsite="cmd" gear="{_vec(np.eye(6)[i])}" '
        f'gaintype="fixed" gainprm="0" biastype="affine" biasprm="0 0 0"/>'
        for i, ax in enumerate(("x", "y", "z", "rx", "ry", "rz"))
    )
    ft = "\n".join(
        f'<general name="ft_{ax}" site="tcp" gear="{_vec(np.eye(6)[i])}" '
        f'gaintype="fixed" gainprm="1" biastype="none"/>'
        for i, ax in enumerate(("x", "y", "z", "rx", "ry", "rz"))
    )
    jnt = "\n".join(
        f'<general name="jnt_{j}" joint="{j}" gaintype="fixed" gainprm="0" '
        f'biastype="affine" biasprm="0 0 0"/>'
        for j in ARM_JOINTS
    )
    return f"""<mujoco model="ffexp_lwr4p_airbed">
<compiler angle="radian" autolimits="true"/>
<option timestep="{_f(ph.timestep)}" integrator="{ph.integrator}" cone="elliptic"
        impratio="{_f(ph.impratio)}" solver="Newton" iterations="{ph.iterations}"
        tolerance="{_f(ph.tolerance)}" gravity="0 0 {_f(-ph.gravity)}"/>
<size memory="8M"/>
<default>
  <default class="funnel">
    <geom condim="3" friction="{_f(ct.friction)} 0.005 0.0001" solref="-1000 -60"
          margin="{_f(TOUCH_MARGIN)}" gap="{_f(TOUCH_MARGIN)}"
          solimp="{_f(ct.impedance)} {_f(ct.impedance)} 0.001 0.5 2" mass="0"
          rgba="0.3 0.5 0.9 1"/>
  </default>
  <default class="pad">
    <geom condim="{pad_condim}" friction="{_f(mu)} 0.005 0.0001" solref="0.004 1"
          solimp="0.95 0.99 0.001 0.5 2" mass="0" rgba="0.2 0.2 0.2 1"/>
  </default>
</default>
<worldbody>
<geom name="glass" type="plane" size="3 3 0.01" pos="0 0 {_f(glass_z)}" {_GLASS}
      friction="{_f(mu)} 0.005 0.0001" solref="0.004 1" solimp="0.95 0.99 0.001 0.5 2"
      rgba="0.8 0.9 1 0.3"/>
<body name="cmd_frame" mocap="true"><site name="cmd"/></body>
{arm_xml(scene)}
{target}
</worldbody>
<actuator>
{jnt}
{cart}
{ft}
</actuator>
<sensor>
<force name="{FT_SENSOR_FORCE}" site="ft_site" nsample="{scene.substeps}"/>
<torque name="{FT_SENSOR_TORQUE}" site="ft_site" nsample="{scene.substeps}"/>
</sensor>
</mujoco>
"""
