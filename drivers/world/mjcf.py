"""MJCF of the rig, generated from a :class:`~drivers.description.scene.Scene`.

Written by us from published numbers; no third-party model file is copied.

The arm's numbers are its published description (:data:`drivers.description.lwr4.LWR4`,
with their sources); the Jubien friction and rotor inertias are scaled by the
scene (the choices made where sources are silent: ``drivers/world/NOTES.md``). The
ATI Mini45: 45 mm diameter, 15.7 mm height, 0.0917 kg (ATI catalogue). Where the
target goes: :func:`drivers.description.layout.compute_layout`.

The TCF (site ``tcp``) is the flange frame turned by 180 deg about the tool
axis and moved to the tool tip: in the paper pose (flange along world +x) TCF
X points up, Y along world -y, Z along world +x. The sensor site ``ft_site``
has the same axes, on the Mini45's tool-side face.

MuJoCo choices (fact sheet sec. 3): ``implicitfast``, elliptic cones,
Newton; the funnels are spheres (tool) against thin boxes (target), a
primitive pair (:mod:`drivers.world.funnels`); the target moves in the bed
plane on x/y slides and a z hinge at its centre of mass, plus a z slide so
that four sphere pads carry its weight on the glass and bed friction is
isotropic Coulomb friction ``mu * m * g``.
The KRC's Cartesian impedance law is built from MuJoCo actuators so it runs
inside the physics step (see :mod:`drivers.world.world`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import mujoco
import numpy as np

from drivers.description.arm import rpy_matrix
from drivers.description.funnel import tool_tip_offset
from drivers.description.layout import Layout
from drivers.description.scene import ObjectSettings, Scene
from drivers.world import funnels
from drivers.world.funnels import mjcf_num as _f
from drivers.world.funnels import mjcf_vec as _vec
from drivers.world.rendered import flange_xml

#: The arm's joint names (``a1`` .. ``a7``; the first six for a six-joint arm).
ARM_JOINTS = tuple(f"a{i + 1}" for i in range(7))
#: The last link's drawn capsule ends this far from the flange's joint (not a physical size).
_FLANGE_CAPSULE = (0.0, 0.0, 0.02)
#: The air-bed target's joints (slides along world x, y, z and a hinge about the vertical).
TARGET_JOINTS = ("target_x", "target_y", "target_z", "target_yaw")
#: The free target's joint (``target.support = "free"``).
TARGET_FREE_JOINT = "target_free"
#: The scene's free-moving bodies, reported by the simulator's truth under these names.
TARGET_BODY = "target"
#: The floating base (``base.mode`` not ``"fixed"``): the chaser spacecraft, its free joint.
BASE_BODY = "chaser"
BASE_FREE_JOINT = "chaser_free"
#: A floating base's sites on the arm's base (link0): the commanded frame, and the frame
#: the superposed wrench acts in (turned to the TCF every cycle).
CMD_SITE = "cmd"
FT_REF_SITE = "ft_ref"
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
# An object collides with the tool as the target's funnel does (drivers.world.funnels).
_OBJECT = 'contype="2" conaffinity="1"'


def arm_xml(scene: Scene) -> str:
    """The scene's arm (``arm.model``) with sensor and tool, as nested bodies."""
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
    lwr = arm.description
    origins = (*lwr.joint_origins_m, _FLANGE_CAPSULE)
    rotors = lwr.rotor_inertias_kgm2 or (0.0,) * lwr.joints  # none published: none
    turns = lwr.joint_rpy_rad
    if turns is not None:  # a DH arm: the flange turned in the last link (the tool on it)
        inner = (f'<body name="flange" pos="{_vec(lwr.flange_m)}" '
                 f'quat="{_vec(_quat(lwr.flange_rpy_rad))}">\n{inner}\n</body>')
        origins = (*lwr.joint_origins_m, lwr.flange_m)
    for i in reversed(range(lwr.joints)):
        lim = math.radians(lwr.position_limits_deg[i])
        low = -lim if lwr.position_lower_deg is None else math.radians(lwr.position_lower_deg[i])
        tl = arm.torque_limits[i]
        joint = (
            f'<joint name="{ARM_JOINTS[i]}" axis="{_vec(lwr.joint_axes[i])}" '
            f'range="{_f(low)} {_f(lim)}" '
            f'frictionloss="{_f(coul[i])}" damping="{_f(visc[i])}" '
            f'armature="{_f(rotors[i] * arm.rotor_fraction())}" '
            f'actuatorfrcrange="{_f(-tl)} {_f(tl)}" actuatorgravcomp="true" '
            # stiff friction constraint: creep below breakaway ~20 um/s instead of ~2 mm/s
            f'solreffriction="{_f(max(0.002, 2 * scene.physics.timestep))} 1" '
            f'solimpfriction="0.99 0.999 0.001"/>'
        )
        turn = "" if turns is None else f' quat="{_vec(_quat(turns[i]))}"'
        inner = (
            f'<body name="link{i + 1}" pos="{_vec(origins[i])}"{turn} gravcomp="1">\n'
            f'<inertial pos="{_vec(lwr.link_coms_m[i])}" mass="{_f(lwr.link_masses_kg[i])}" '
            f'diaginertia="{_vec(lwr.link_inertias_kgm2[i])}"/>\n'
            f"{joint}\n"
            f"{_link_capsule(origins[i + 1])}"
            f"{inner}\n</body>"
        )
    if scene.base.floating:
        return _floating_base_xml(scene, inner)
    base = _vec(arm.base_pos)
    return (
        f'<body name="link0" pos="{base}">\n'
        f'<geom type="cylinder" size="0.06 0.055" pos="0 0 0.055" {_VISUAL} mass="0"/>\n'
        f"{inner}\n</body>"
    )


def _link_capsule(to: Sequence[float]) -> str:
    """The link's drawing, a capsule to the next joint (none where that joint sits at
    this one's origin, as two of the FR3's do)."""
    if not any(to):
        return ""
    return (f'<geom type="capsule" size="0.06" fromto="0 0 0 {_vec(to)}" {_VISUAL} '
            f'mass="0" rgba="1 0.5 0 0.6"/>\n')


def _full(i: np.ndarray) -> str:
    """MJCF ``fullinertia`` of a 3x3 tensor."""
    return _vec((i[0, 0], i[1, 1], i[2, 2], i[0, 1], i[0, 2], i[1, 2]))


def _floating_base_xml(scene: Scene, arm: str) -> str:
    """The arm on a free-floating spacecraft: a free body whose top face carries link0 at
    ``arm.base_pos``, with the commanded frame and the wrench's frame as sites of link0."""
    b = scene.base
    sx, sy, sz = b.size
    centre = np.asarray(scene.arm.base_pos) - np.array([0.0, 0.0, sz / 2.0])
    return (
        f'<body name="{BASE_BODY}" pos="{_vec(centre)}">\n'
        f'<freejoint name="{BASE_FREE_JOINT}"/>\n'
        f'<inertial pos="0 0 0" mass="{_f(b.mass)}" fullinertia="{_full(b.inertia_matrix())}"/>\n'
        f'<geom type="box" size="{_f(sx / 2)} {_f(sy / 2)} {_f(sz / 2)}" {_VISUAL} mass="0" '
        f'rgba="0.85 0.75 0.3 1"/>\n'
        f'<body name="link0" pos="0 0 {_f(sz / 2)}">\n'
        f'<site name="{CMD_SITE}"/>\n<site name="{FT_REF_SITE}"/>\n'
        f'<geom type="cylinder" size="0.06 0.055" pos="0 0 0.055" {_VISUAL} mass="0"/>\n'
        f"{arm}\n</body>\n</body>"
    )


def _quat(rpy: object) -> np.ndarray:
    """MuJoCo's ``w x y z`` quaternion of a roll-pitch-yaw turn."""
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, rpy_matrix(rpy).ravel())  # type: ignore[arg-type]
    return quat


def _free_target_xml(scene: Scene, layout: Layout) -> str:
    """A target in free flight: a free joint, weightless (``gravcomp``), no pads or hose."""
    tg = scene.target
    sx, sy, sz = tg.size
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(layout.target_rot).ravel())
    mass, inertia = tg.mass, tg.inertia_matrix()
    flange = ""
    if scene.carrier.render_target:  # the carrier's mock-up, welded to its flange
        mass = max(scene.carrier.mockup_mass_kg, 1e-6)
        inertia = inertia * (mass / tg.mass)
        flange = flange_xml(scene, _vec(layout.target_pos), _vec(quat), TARGET_BODY)[0]
    return flange + (
        f'<body name="{TARGET_BODY}" pos="{_vec(layout.target_pos)}" quat="{_vec(quat)}" '
        f'gravcomp="1">\n'
        f'<freejoint name="{TARGET_FREE_JOINT}"/>\n'
        f'<inertial pos="0 0 0" mass="{_f(mass)}" '
        f'fullinertia="{_full(inertia)}"/>\n'
        f'<geom type="box" size="{_f(sx / 2)} {_f(sy / 2)} {_f(sz / 2)}" {_VISUAL} mass="0" '
        f'rgba="0.75 0.75 0.8 1"/>\n'
        f'<body name="target_funnel" pos="{_vec(layout.funnel_in_target)}">\n'
        f'<site name="funnel_mouth" pos="0 0 0"/>\n'
        f"{funnels.target_funnel_geoms(tg.funnel, 'funnel')}\n</body>\n</body>"
    )


def _object_xml(obj: ObjectSettings, centre: np.ndarray) -> str:
    """One of the scene's objects: a primitive the tool touches, free or fixed."""
    m = obj.mass
    a, b, c = obj.size
    if obj.shape == "box":
        geom = f'type="box" size="{_f(a / 2)} {_f(b / 2)} {_f(c / 2)}"'
        inertia = (m * (b**2 + c**2) / 12, m * (a**2 + c**2) / 12, m * (a**2 + b**2) / 12)
    elif obj.shape == "sphere":
        geom = f'type="sphere" size="{_f(a / 2)}"'
        inertia = (m * a**2 / 10,) * 3
    else:
        r = a / 2
        geom = f'type="cylinder" size="{_f(r)} {_f(c / 2)}"'
        inertia = (m * (3 * r**2 + c**2) / 12, m * (3 * r**2 + c**2) / 12, m * r**2 / 2)
    free = obj.support == "free"
    sites = "".join(f'<site name="{obj.name}.{site}" pos="{_vec(pos)}"/>\n'
                    for site, pos in obj.sites.items())
    weightless = ' gravcomp="1"' if free else ""
    return (
        f'<body name="{obj.name}" pos="{_vec(centre)}"{weightless}>\n'
        + (f'<freejoint name="{obj.name}_free"/>\n' if free else "")
        + f'<inertial pos="0 0 0" mass="{_f(m)}" diaginertia="{_vec(inertia)}"/>\n'
        f'<geom name="{obj.name}" {geom} class="funnel" {_OBJECT} rgba="0.4 0.7 0.4 1"/>\n'
        f"{sites}</body>"
    )


def objects_xml(scene: Scene, layout: Layout) -> str:
    """The scene's ``[[objects]]``."""
    return "\n".join(_object_xml(o, layout.objects[o.name]) for o in scene.objects)


def target_xml(scene: Scene, layout: Layout) -> str:
    """The target body on its support (:attr:`TargetSettings.support
    <drivers.description.scene.TargetSettings.support>`)."""
    tg = scene.target
    if tg.support == "free":
        return _free_target_xml(scene, layout)
    sx, sy, sz = tg.size
    m = tg.mass
    inertia = (m * (sy**2 + sz**2) / 12.0, m * (sx**2 + sz**2) / 12.0, m * (sx**2 + sy**2) / 12.0)
    body_inertia = f'diaginertia="{_vec(inertia)}"'
    if tg.inertia is not None:
        body_inertia = f'fullinertia="{_full(tg.inertia_matrix())}"'
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
        f'<inertial pos="0 0 0" mass="{_f(m)}" {body_inertia}/>\n'
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


def build_xml(scene: Scene, layout: Layout | None) -> str:
    """The whole model. With ``layout=None`` only the arm (used to find the start TCF)."""
    ph = scene.physics
    ct = scene.contact
    target = "" if layout is None else target_xml(scene, layout) + objects_xml(scene, layout)
    glass_z = 0.0 if layout is None else layout.glass_z
    mu = scene.target.mu
    glass = "" if scene.target.support == "free" else (
        f'<geom name="glass" type="plane" size="3 3 0.01" pos="0 0 {_f(glass_z)}" {_GLASS}\n'
        f'      friction="{_f(mu)} 0.005 0.0001" solref="0.004 1" '
        f'solimp="0.95 0.99 0.001 0.5 2"\n      rgba="0.8 0.9 1 0.3"/>')
    pad_condim = 3 if mu > 0.0 else 1
    equality = ""
    if layout is not None and scene.target.support == "free" and scene.carrier.render_target:
        equality = flange_xml(scene, "0 0 0", "1 0 0 0", TARGET_BODY)[1]
    cart = "\n".join(
        f'<general name="cart_{ax}" site="tcp" refsite="cmd" gear="{_vec(np.eye(6)[i])}" '
        f'gaintype="fixed" gainprm="0" biastype="affine" biasprm="0 0 0"/>'
        for i, ax in enumerate(("x", "y", "z", "rx", "ry", "rz"))
    )
    # On a floating base the superposed wrench acts between the TCP and the arm's base
    # (joint torques, internal to the spacecraft), along the axes of a base site turned
    # to the TCF every cycle; on a fixed base it acts at the TCP in the TCF.
    ref = f' refsite="{FT_REF_SITE}"' if scene.base.floating else ""
    ft = "\n".join(
        f'<general name="ft_{ax}" site="tcp"{ref} gear="{_vec(np.eye(6)[i])}" '
        f'gaintype="fixed" gainprm="1" biastype="none"/>'
        for i, ax in enumerate(("x", "y", "z", "rx", "ry", "rz"))
    )
    cmd_frame = "" if scene.base.floating else (
        f'<body name="cmd_frame" mocap="true"><site name="{CMD_SITE}"/></body>')
    jnt = "\n".join(
        f'<general name="jnt_{j}" joint="{j}" gaintype="fixed" gainprm="0" '
        f'biastype="affine" biasprm="0 0 0"/>'
        for j in ARM_JOINTS[:scene.arm.description.joints]
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
{glass}
{cmd_frame}
{arm_xml(scene)}
{target}
</worldbody>
<actuator>
{jnt}
{cart}
{ft}
</actuator>
{equality}
<sensor>
<force name="{FT_SENSOR_FORCE}" site="ft_site" nsample="{scene.substeps}"/>
<torque name="{FT_SENSOR_TORQUE}" site="ft_site" nsample="{scene.substeps}"/>
</sensor>
</mujoco>
"""
