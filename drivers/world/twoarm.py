"""Both arms of a rendered-target impact in one MuJoCo world (:mod:`drivers.carrier.plant`):
the chaser (the scene's arm, its tool's motion imposed: held stiff) and the carrier
(``carrier.arm``, a joint position servo on every joint), the target's mock-up on the
carrier's flange behind a simulated F/T sensor (MuJoCo's force and torque sensors on the
mock-up's side of the sensor). Written by us from published numbers.

The physics step is ``physics.timestep / BENCH_SUBSTEPS`` (as the point bench's), the
integrator MuJoCo's semi-implicit Euler (``mj_step1`` / ``mj_step2``, so that the contact
force is set between the velocity and the acceleration stage), gravity the lab's
(``carrier.lab_gravity_mps2``; every link compensated, the servo holds no weight; the
sensor still reads the mock-up's weight and inertia, as a real one does).

The joint servo: ``tau = kp (q_ref - q) + kv (qd_ref - qd)``, ``kp = I w^2``,
``kv = 2 z I w`` with each joint's own inertia ``I`` at the start pose (the mass matrix'
diagonal), ``w = 2 pi carrier.servo_bandwidth_hz`` and ``z = carrier.servo_damping_ratio``,
clipped at the arm's published torque limits; the reference moves linearly from the last
target to the new one over the cycle, as a servoJ's interpolation (reached at the cycle's
end), at the target's velocity.

The contact between the chaser's tool tip and the mock-up's -x face is the impact
protocol's: a unilateral spring-damper ``max(0, k d + c d')`` of ``contact.stiffness``,
its damping from ``contact.restitution`` for the effective mass at the contact point
(:func:`drivers.description.impact.damping_ratio_for`), applied at the tip on the
mock-up. MuJoCo's own contact is not used for it: its force is set in acceleration
space, so its stiffness in N/m would follow the carrier's reflected mass, not the scene.
The F/T sensor samples at ``ft_sensor.rate`` with ``ft_sensor.noise_std`` and each sample
reaches the loop ``ft_sensor.delay_s`` later.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from drivers.base.types import F64
from drivers.carrier.bench import BENCH_SUBSTEPS
from drivers.carrier.kinematics import ArmChain
from drivers.carrier.plant import ArmLayout, PlantCycle
from drivers.description.arm import rpy_matrix
from drivers.description.impact import damping_ratio_for
from drivers.description.scene import Scene, inertia_tensor
from drivers.errors import ConfigError

__all__ = ["TwoArmWorld", "two_arm_xml"]


def _f(v: float) -> str:
    return f"{v:.12g}"


def _vec(v: object) -> str:
    return " ".join(_f(float(x)) for x in v)  # type: ignore[attr-defined]


def _quat(rot: F64) -> F64:
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(rot).ravel())
    return q


def _chain_xml(prefix: str, chain: ArmChain, end: str) -> str:
    """An arm's links as nested bodies (joints ``<prefix>a1`` ..), ``end`` in its flange."""
    arm = chain.arm
    turns = arm.joint_rpy_rad or ((0.0, 0.0, 0.0),) * arm.joints
    inner = (f'<body name="{prefix}flange" pos="{_vec(arm.flange_m)}" '
             f'quat="{_vec(_quat(rpy_matrix(arm.flange_rpy_rad)))}">\n{end}\n</body>')
    for i in reversed(range(arm.joints)):
        inertia = arm.link_inertias_kgm2[i]
        inner = (
            f'<body name="{prefix}link{i + 1}" pos="{_vec(arm.joint_origins_m[i])}" '
            f'quat="{_vec(_quat(rpy_matrix(turns[i])))}" gravcomp="1">\n'
            f'<inertial pos="{_vec(arm.link_coms_m[i])}" mass="{_f(arm.link_masses_kg[i])}" '
            f'diaginertia="{_vec(inertia)}"/>\n'
            f'<joint name="{prefix}a{i + 1}" axis="{_vec(arm.joint_axes[i])}"/>\n'
            f'{inner}\n</body>')
    return f'<body name="{prefix}base" pos="{_vec(chain.base_m)}">\n{inner}\n</body>'


def two_arm_xml(scene: Scene, layout: ArmLayout) -> str:
    """The world's MJCF."""
    tip = layout.chaser.tool[:3, 3]
    chaser_end = (f'<geom type="capsule" size="0.012" fromto="0 0 0 {_vec(tip)}" '
                  f'contype="0" conaffinity="0" mass="0"/>\n<site name="chaser_tip" '
                  f'pos="{_vec(tip)}"/>')
    sx, sy, sz = scene.target.size
    m = scene.carrier.mockup_mass_kg
    inertia = (m * (sy**2 + sz**2) / 12.0, m * (sx**2 + sz**2) / 12.0,
               m * (sx**2 + sy**2) / 12.0)
    mount = layout.mount
    mockup_inertial = (f'<inertial pos="0 0 0" mass="{_f(m)}" diaginertia="{_vec(inertia)}"/>'
                       if m > 0.0 else
                       '<inertial pos="0 0 0" mass="1e-6" diaginertia="1e-9 1e-9 1e-9"/>')
    carrier_end = (
        f'<body name="mockup" pos="{_vec(mount[:3, 3])}" quat="{_vec(_quat(mount[:3, :3]))}" '
        f'gravcomp="1">\n{mockup_inertial}\n'
        f'<geom type="box" size="{_f(sx / 2)} {_f(sy / 2)} {_f(sz / 2)}" contype="0" '
        f'conaffinity="0" mass="0" rgba="0.75 0.75 0.8 1"/>\n'
        f'<site name="carrier_ft" pos="{_vec(layout.sensor_in_mockup_m)}"/>\n</body>')
    h = scene.physics.timestep / BENCH_SUBSTEPS
    g = scene.carrier.lab_gravity_mps2
    acts = "\n".join(
        f'<general name="carrier_servo{i + 1}" joint="carrier_a{i + 1}" gaintype="fixed" '
        f'gainprm="0" biastype="affine" biasprm="0 0 0" forcelimited="true" '
        f'forcerange="{_f(-lim)} {_f(lim)}"/>'
        for i, lim in enumerate(layout.torque_limits_nm))
    return f"""<mujoco model="ffexp_two_arms">
<compiler angle="radian" autolimits="true"/>
<option timestep="{_f(h)}" integrator="Euler" gravity="0 0 {_f(-g)}"/>
<worldbody>
{_chain_xml("chaser_", layout.chaser, chaser_end)}
{_chain_xml("carrier_", layout.carrier, carrier_end)}
</worldbody>
<actuator>
{acts}
</actuator>
<sensor>
<force name="carrier_force" site="carrier_ft"/>
<torque name="carrier_torque" site="carrier_ft"/>
</sensor>
</mujoco>
"""


class TwoArmWorld:
    """The two-arm world (:class:`drivers.carrier.plant.CarrierPlant`)."""

    def __init__(self, scene: Scene, layout: ArmLayout, seed: int = 0, *,
                 push: tuple[float, float, F64] | None = None) -> None:
        """``push``: ``(from_s, to_s, wrench)``, a wrench (world frame, about the mock-up's
        centre) applied to the mock-up over that time besides the contact (a known load
        for tests)."""
        self.scene, self.layout = scene, layout
        self._push = push
        self.model = mujoco.MjModel.from_xml_string(two_arm_xml(scene, layout))
        self.data = mujoco.MjData(self.model)
        m = self.model
        self.h = m.opt.timestep
        cs = scene.carrier
        self.n_cycle = self._multiple("carrier.cycle_s", cs.cycle_s)
        self.n_ft = self._multiple("ft_sensor.rate", 1.0 / scene.ft_sensor.rate)
        self.n_delay = round(scene.ft_sensor.delay_s / self.h)
        jid = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"{p}a{i + 1}")
               for p, n in (("chaser_", layout.chaser.arm.joints),
                            ("carrier_", layout.carrier.arm.joints)) for i in range(n)]
        nc = layout.chaser.arm.joints
        self._chaser_q = np.array([m.jnt_qposadr[j] for j in jid[:nc]])
        self._chaser_v = np.array([m.jnt_dofadr[j] for j in jid[:nc]])
        self._carrier_q = np.array([m.jnt_qposadr[j] for j in jid[nc:]])
        self._carrier_v = np.array([m.jnt_dofadr[j] for j in jid[nc:]])
        d = self.data
        d.qpos[self._chaser_q] = layout.chaser_q0
        d.qpos[self._carrier_q] = layout.carrier_q0
        mujoco.mj_forward(m, d)
        full = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, full)
        inertia = np.diag(full)[self._carrier_v]
        w = 2.0 * math.pi * cs.servo_bandwidth_hz
        self.kp = inertia * w * w
        self.kv = 2.0 * cs.servo_damping_ratio * inertia * w
        m.actuator_gainprm[:, 0] = self.kp
        m.actuator_biasprm[:, 1] = -self.kp
        m.actuator_biasprm[:, 2] = -self.kv
        self._mockup = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "mockup")
        self._tip = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "chaser_tip")
        self._ft = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "carrier_ft")
        self._half = 0.5 * scene.target.size[0]
        self._face_half = 0.5 * np.array(scene.target.size[1:])
        k = scene.contact.stiffness
        tg = scene.target
        inertia_t = inertia_tensor(tg.mass, tg.size, tg.inertia)
        from drivers.carrier.body import cross3

        lever = cross3(np.array([-self._half, -float(layout.centre_m[1] - self._tip0()[1]),
                                 0.0]), np.array([1.0, 0.0, 0.0]))
        m_eff = 1.0 / (1.0 / tg.mass + float(lever @ np.linalg.solve(inertia_t, lever)))
        self.k, self.c = k, 2.0 * damping_ratio_for(scene.contact.restitution) * math.sqrt(
            k * m_eff)
        self._rng = np.random.default_rng(seed)
        self._noise = np.array(scene.ft_sensor.noise_std)[[0, 0, 0, 1, 1, 1]]
        self._pending: list[tuple[int, float, F64]] = []
        self._i = 0
        self._ref_q = layout.carrier_q0.copy()
        self._chaser_ref = layout.chaser_q0.copy()
        self._buf6 = np.zeros(6)

    def _tip0(self) -> F64:
        return np.asarray(self.layout.chaser.pose(self.layout.chaser_q0)[:3, 3])

    def _multiple(self, name: str, value: float) -> int:
        n = value / float(self.model.opt.timestep)
        if abs(n - round(n)) > 1e-6 or round(n) < 1:
            raise ConfigError(self.scene.name, name, f"{value:g} s is not a multiple of "
                              f"physics.timestep / {BENCH_SUBSTEPS} = "
                              f"{self.model.opt.timestep:g} s")
        return round(n)

    def _cycle(self, fine: list[tuple[float, ...]], samples: list[tuple[float, F64]]
               ) -> PlantCycle:
        d = self.data
        return PlantCycle(self._i * self.h, d.qpos[self._carrier_q].copy(),
                          d.qvel[self._carrier_v].copy(), samples, fine)

    def start(self) -> PlantCycle:
        return self._cycle([], [])

    def close(self) -> None:
        """Nothing to release."""

    def step(self, carrier_q: F64, carrier_qd: F64, chaser_q: F64,
             chaser_qd: F64) -> PlantCycle:
        m, d = self.model, self.data
        n = self.n_cycle
        q0, c0 = self._ref_q, self._chaser_ref
        dq, dc = np.asarray(carrier_q) - q0, np.asarray(chaser_q) - c0
        v_chaser = dc / (n * self.h)
        fine: list[tuple[float, ...]] = []
        samples: list[tuple[float, F64]] = []
        centre = self.layout.centre_m
        for j in range(n):
            i = self._i
            d.qpos[self._chaser_q] = c0 + dc * (j / n)
            d.qvel[self._chaser_v] = v_chaser
            ref = q0 + dq * ((j + 1) / n)
            d.ctrl[:] = ref + (self.kv / self.kp) * np.asarray(carrier_qd)
            mujoco.mj_step1(m, d)
            fine.append(self._contact(i * self.h, centre))
            mujoco.mj_step2(m, d)
            if i % self.n_ft == 0:
                self._pending.append((i + self.n_delay, i * self.h, self._reading()))
            self._i = i + 1
            due = [p for p in self._pending if p[0] <= self._i]
            if due:
                self._pending = [p for p in self._pending if p[0] > self._i]
                samples.extend((ts, w) for _, ts, w in due)
        self._ref_q = np.asarray(carrier_q, dtype=np.float64).copy()
        self._chaser_ref = np.asarray(chaser_q, dtype=np.float64).copy()
        d.qpos[self._chaser_q] = self._chaser_ref
        return self._cycle(fine, samples)

    def _contact(self, t_s: float, centre: F64) -> tuple[float, ...]:
        """The tool tip against the mock-up's -x face: the force applied on the mock-up
        (held over the step) and the step's truth row."""
        m, d = self.model, self.data
        b = self._mockup
        tip = d.site_xpos[self._tip]
        c = d.xpos[b]
        rot = d.xmat[b].reshape(3, 3)
        n_w = rot[:, 0]
        r = tip - c
        depth = float(r @ n_w) + self._half
        lateral = rot.T @ r
        inside = abs(lateral[1]) <= self._face_half[0] and abs(lateral[2]) <= self._face_half[1]
        mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_BODY, b, self._buf6, 0)
        w, v_c = self._buf6[:3].copy(), self._buf6[3:].copy()
        v_pt = v_c + np.cross(w, r)
        mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_SITE, self._tip, self._buf6, 0)
        v_tip = self._buf6[3:]
        closing = float((v_tip - v_pt) @ n_w)
        f = max(0.0, self.k * depth + self.c * closing) if depth > 0.0 and inside else 0.0
        force = f * n_w
        d.xfrc_applied[b, :3] = force
        d.xfrc_applied[b, 3:] = np.cross(r, force)
        if self._push is not None and self._push[0] <= t_s < self._push[1]:
            d.xfrc_applied[b] += self._push[2]
        return (t_s, depth, f, float(v_pt @ n_w), float(tip[0] - centre[0]))

    def _reading(self) -> F64:
        """The sensor's sample: the force the mock-up puts on the sensor and its torque
        about the mock-up's centre (world frame), with the sensor's noise."""
        d = self.data
        rot = d.site_xmat[self._ft].reshape(3, 3)
        force = -(rot @ d.sensordata[0:3])
        torque = -(rot @ d.sensordata[3:6])
        torque = torque + np.cross(d.site_xpos[self._ft] - d.xpos[self._mockup], force)
        out: F64 = np.concatenate((force, torque)) + self._noise * self._rng.standard_normal(6)
        return out
