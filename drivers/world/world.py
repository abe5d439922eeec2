"""The simulated rig: the scene's arm with the KRC's impedance law, air-bed target, F/T sensor.

:class:`SimWorld` is a physics world only: ``step(command)`` latches an ArmCommand (if
given), runs one control cycle of physics and returns the ArmState (:mod:`drivers.world.arm`) at
its end. It knows no link protocol: how FRI's flags select fields, when the link takes commands
(MON/CMD) and its quality are the emulator's (:mod:`drivers.emulate`). Its rig is a Scene.

How the KRC is modelled (see :mod:`drivers.base.impedance` for the laws):

* The command is held for the cycle (zero-order hold). The KRC's own
  impedance loop runs much faster than FRI; here it runs at the physics rate,
  built from MuJoCo actuators so that it costs nothing in Python:
  six ``general`` actuators on the TCP site with the commanded frame as
  ``refsite`` (a mocap site) realise ``K (x_cmd - x_msr) - D xdot`` per axis
  of the commanded frame; six force actuators on the TCP site realise
  ``F_cmd`` in the TCF (``addTcpFT``); seven joint actuators realise joint
  impedance / position mode and ``addJntTrq``.
* D is set once per cycle from the Cartesian inertia, recomputed whenever a
  joint has moved more than :data:`INERTIA_REUSE_RAD` from where it was last
  computed (the damping's error stays below 0.1 %). f_dyn: gravity is
  compensated exactly every physics step (body ``gravcomp``, routed through
  the actuators so the torque limits apply); Coriolis/centrifugal terms are
  computed once per cycle and held.
* Joint torque limits clamp the total actuator torque per joint
  (``actuatorfrcrange``); joint Coulomb and viscous friction act link-side.

Honest differences from the real KRC: the real Cartesian stiffness acts in
the TCF and its exact rotational error metric is not public (here: the
commanded frame's axes, MuJoCo's rotation-vector metric; the two agree to
first order in the pose error); no null-space stiffness is modelled (the
redundant elbow is held by joint friction only); estimated external
torques/wrench are exact (no torque-sensor noise or model error).
"""

from __future__ import annotations

import weakref
from collections.abc import Callable

import mujoco
import numpy as np

from drivers.base.types import F64, FtSamples
from drivers.description import Scene, compute_layout, tool_tip_offset
from drivers.errors import SimulationError
from drivers.world import mjcf
from drivers.world.actuate import apply
from drivers.world.arm import ArmCommand, ArmMode
from drivers.world.bodies import FreeBodies
from drivers.world.chaser import FloatingBase
from drivers.world.contact import ToolContact, configure_contact
from drivers.world.divergence import check_divergence, quiet_divergence
from drivers.world.friction import JointFriction
from drivers.world.ftsensor import FtSensorModel, FtSteps
from drivers.world.latch import take
from drivers.world.rendered import RenderedTarget
from drivers.world.state import LazyArmState, StateFill
from drivers.world.truth import pose as _pose

#: The KRC's damping uses the Cartesian inertia of the configuration where it was
#: last computed until a joint has moved this far from it [rad]. Measured pressing
#: into the funnel: 1 mrad keeps the damping within 0.06 % of the exact value
#: (3 mrad: 0.4 %; 10 mrad: off by up to 8x near a poorly conditioned axis).
INERTIA_REUSE_RAD = 1e-3

# np.linalg.inv's LAPACK gufunc without its Python wrapper (the same values); the
# module is private: without it, the public function
_inv: Callable[..., F64] = getattr(getattr(np.linalg, "_umath_linalg", None), "inv", np.linalg.inv)


#: kernels.post_step's answer bits (POST_TOUCHING, POST_DIVERGED, POST_INERTIA)
_TOUCHING, _DIVERGED, _INERTIA = 1, 2, 4
_NO_GEOM = np.zeros((1, 4), dtype=np.int32)[:0, ::2]  # no contact (a strided view, as MuJoCo's)


def _no_state() -> LazyArmState | None:
    return None


_MODES = {
    "cart_impedance": ArmMode.CART_IMPEDANCE,
    "joint_position": ArmMode.JOINT_POSITION,
    "joint_impedance": ArmMode.JOINT_IMPEDANCE,
}


class SimWorld:
    """The physics world, stepped one control cycle (``scene.fri.cycle``) at a time.

    Args:
        scene: the rig.
        seed: overrides ``scene.seed``; same seed and same commands give
            bit-identical states and F/T samples.
    """

    def __init__(self, scene: Scene, seed: int | None = None) -> None:
        self.scene = scene
        self.seed = scene.seed if seed is None else seed
        self.rng = np.random.default_rng(self.seed)
        self.dt = scene.physics.timestep
        self.substeps = scene.substeps
        self.cycle_ns = round(scene.fri.cycle * 1e9)
        self.step_ns = round(self.dt * 1e9)
        self._n = n = scene.arm.description.joints  # the scene's arm (arm.model)

        # 1. Arm alone: where is the TCF at the start pose?
        m0 = mujoco.MjModel.from_xml_string(mjcf.build_xml(scene, None))
        d0 = mujoco.MjData(m0)
        q0 = int(m0.jnt_qposadr[mujoco.mj_name2id(m0, mujoco.mjtObj.mjOBJ_JOINT, "a1")])
        d0.qpos[q0:q0 + n] = scene.arm.q_init
        mujoco.mj_forward(m0, d0)
        tcp0 = d0.site("tcp")
        self.layout = compute_layout(scene, tcp0.xpos.copy(), tcp0.xmat.reshape(3, 3).copy())

        # 2. The whole rig.
        self.xml = mjcf.build_xml(scene, self.layout)
        self.model = m = mujoco.MjModel.from_xml_string(self.xml)
        self.data = d = mujoco.MjData(m)
        self._ready = False
        quiet_divergence(m, d)
        a1 = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "a1")
        # the arm's joints in qpos and qvel (after a floating base's free joint)
        self._qa = qa = slice(int(m.jnt_qposadr[a1]), int(m.jnt_qposadr[a1]) + n)
        self._va = va = slice(int(m.jnt_dofadr[a1]), int(m.jnt_dofadr[a1]) + n)
        self._friction = JointFriction.of_arm(scene.arm)
        self._friction.install(m, va.start)
        self._frictionloss = m.dof_frictionloss[va]
        self._tcp = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "tcp")
        self._ft_site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "ft_site")
        self._mouth = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "funnel_mouth")
        self._target_body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, mjcf.TARGET_BODY)
        self._tool_body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "tool")
        self.chaser = FloatingBase(scene.base, m, d) if scene.base.floating else None
        """The floating base (``None``: the arm stands on the ground)."""
        self.bodies = FreeBodies(m, d, (
            mjcf.TARGET_BODY, *(() if self.chaser is None else (mjcf.BASE_BODY,)),
            *(o.name for o in scene.objects if o.support == "free")))
        self._object_sites = [  # (name, id) of each object's named frame
            (name, mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, name))
            for name in (f"{o.name}.{site}" for o in scene.objects for site in o.sites)]
        """The scene's free-moving bodies (the truth reports them by name)."""
        self._attached = self.bodies.attached({"funnel_mouth": self._mouth,
                                               **dict(self._object_sites)})
        """The named frames fixed on a free body (the truth's ``attached``)."""
        self._on_bed = scene.target.support == "air_bed"
        if self._on_bed:  # the bed's slides and hinge
            jid = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n)
                   for n in mjcf.TARGET_JOINTS]
            self._t_qadr = np.array([m.jnt_qposadr[j] for j in jid])
            self._t_vadr = np.array([m.jnt_dofadr[j] for j in jid])
        self._tool_geoms = {g for g in range(m.ngeom) if m.geom_bodyid[g] == self._tool_body
                            and m.geom_contype[g] != 0}
        self._funnel_geoms = {
            g for g in range(m.ngeom)
            if m.geom_contype[g] != 0 and m.geom_bodyid[g] != self._target_body
            and (g in self._tool_geoms or m.geom_contype[g] == 2)
        }
        self._act_jnt = slice(0, n)
        self._act_cart = slice(n, n + 6)
        self._act_ft = slice(n + 6, n + 12)
        self._vel_limits = np.radians(scene.arm.description.velocity_limits_degps)
        self._pos_limits = np.radians(scene.arm.description.position_limits_deg)
        self._pos_lower = np.radians(scene.arm.description.lower_limits_deg)
        self._torque_limits = np.asarray(scene.arm.torque_limits)
        from drivers.world import kernels  # numba: imported when a world is built
        # MuJoCo's functions called from compiled code, on these structs (kernels.py)
        self._mj = (kernels.mujoco_addresses(), m._address, d._address)
        self._end_state, self._tcf_kinematics = kernels.end_state, kernels.tcf_kinematics
        self._post_step, self._set_frame = kernels.post_step, kernels.set_frame
        self._inertia_lhs, self._same_or_finite = kernels.inertia_lhs, kernels.same_or_finite
        self._arm_warnings = kernels.arm_warnings  # the state's, from these limits:
        self._warn_limits = np.array((self._vel_limits, self._pos_limits - 1e-3,
                                      self._pos_lower + 1e-3, self._torque_limits - 1e-9))

        # Preallocated work arrays.
        self._jac2 = np.zeros((2, 3, m.nv))  # MuJoCo's translational, rotational Jacobian
        self._mfull = np.zeros((m.nv, m.nv))
        self._jfull = np.zeros((6, m.nv))
        self._jfull2 = self._jfull.reshape(2, 3, m.nv)  # the same memory
        self._minv_jt = np.zeros((6, m.nv))
        self._kin_ok = False
        self._m_ok = True  # qM and its factor are the current state's (mj_forward made them)
        self._damp_work = np.zeros(6)
        self._inertia_new = True
        # views into MuJoCo's buffers written every cycle
        self._cart_damp_prm = m.actuator_biasprm[self._act_cart, 2]
        self._cart_stiff_prm = m.actuator_biasprm[self._act_cart, 1]
        self._jnt_trq_prm = m.actuator_biasprm[self._act_jnt, 0]
        self._ctrl_ft = d.ctrl[self._act_ft]
        if self.chaser is None:  # the commanded frame: a mocap body, or a site of link0
            cmd = int(m.body_mocapid[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY,
                                                       "cmd_frame")])
            self._mocap_pos, self._mocap_quat = d.mocap_pos[cmd], d.mocap_quat[cmd]
        else:
            cmd = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, mjcf.CMD_SITE)
            m.site_sameframe[cmd] = 0  # its pose is written at run time: not its body's
            self._mocap_pos, self._mocap_quat = m.site_pos[cmd], m.site_quat[cmd]
        self._qvel_arm = d.qvel[va]
        self._qpos_arm = d.qpos[qa]
        self._qvel = d.qvel
        self._warn_number = d.warning.number
        self._qacc_arm = d.qacc[va]
        self._actuator_arm = d.qfrc_actuator[va]
        self._tcp_xpos = d.site_xpos[self._tcp]
        self._tcp_xmat = d.site_xmat[self._tcp]
        self._tcp_rot = self._tcp_xmat.reshape(3, 3)  # a view
        self._pose_ok = False  # _tcp_pose is the current state's
        self._mouth_xpos = d.site_xpos[self._mouth]
        self._mouth_xmat = d.site_xmat[self._mouth]
        self._tool_contact = ToolContact(m, d, self._tool_body, self._tool_geoms, self._tcp)
        # what the actuators hold now (the objects last written; None: rewrite)
        self._written: dict[str, object] = {}
        self._k_pos = self._neg_2d = np.zeros(6)  # the damping's factors of K and d (actuate)
        # the last stiffness/damping given and what they became (commands repeat them)
        self._given_k: tuple[bytes, F64, bool] | None = None
        self._given_d: tuple[bytes, F64] | None = None
        self._bias_arm = d.qfrc_bias[va]
        self._qfrc_bias = d.qfrc_bias
        self._gravcomp_arm = d.qfrc_gravcomp[va]
        self._applied_arm = d.qfrc_applied[va]
        self._rot9 = np.zeros(9)
        self._ft_steps = FtSteps(
            m, d, mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, mjcf.FT_SENSOR_FORCE),
            mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, mjcf.FT_SENSOR_TORQUE),
            self.substeps)
        self._ft_raw = self._ft_steps.raw

        # Start state: arm at q_init, target yawed on its hinge (in free flight the
        # body's own orientation is its pose in the model).
        if self._on_bed:
            d.qpos[self._t_qadr[3]] = self.layout.target_yaw
        d.qpos[qa] = scene.arm.q_init
        mujoco.mj_forward(m, d)
        self._update_kinematics()

        # Funnel contact: physical N/m -> MuJoCo direct solref via the effective mass.
        self.contact_info = configure_contact(
            scene, self.model, float(self.cart_inertia[2, 2]), self.dt, self._funnel_geoms)

        # Initial command: hold the start pose with the scene's impedance.
        self.mode = _MODES[scene.fri.control]
        ctl = scene.controller
        self._cart_pos = self.tcp_pose.copy()
        self._cart_stiff = np.asarray(ctl.cart_stiffness, dtype=np.float64)
        self._cart_damp = np.asarray(ctl.cart_damping, dtype=np.float64)
        self._tcp_ft = np.zeros(6)
        self._tcp_ft_key = b""
        self._jnt_pos = d.qpos[qa].copy()
        self._jnt_trq = np.zeros(n)
        self._jnt_stiff = np.full(n, ctl.jnt_position_stiffness)
        self._jnt_damp = np.full(n, ctl.jnt_position_damping)
        self._warning = 0
        self._latched = True
        self._apply()
        if self.chaser is not None:
            self.chaser.hold()
            self.chaser.cycle(self.tcp_pose)

        # Let the target settle on its pads, then start the clock.
        for _ in range(round(scene.physics.settle_time / self.dt)):
            mujoco.mj_step(m, d)
        check_divergence(d)
        d.time = 0.0
        self._ft_steps.restart()
        if self.chaser is not None:
            self.chaser.hold()  # the base holds where it starts
        for obj in scene.objects:
            if obj.support == "free":
                self.bodies.set_free_twist(obj.name, np.asarray(obj.drift_mps),
                                           np.asarray(obj.tumble_radps))
        tg = scene.target
        if self._on_bed:
            self.set_target_velocity(*tg.velocity)
        else:
            self.bodies.set_free_twist(mjcf.TARGET_BODY, np.asarray(tg.drift_mps),
                                       np.asarray(tg.tumble_radps))
        mujoco.mj_forward(m, d)
        self.rendered = RenderedTarget(scene, m, d, self._target_body, self.rng) \
            if scene.carrier.render_target else None
        """The target rendered by the carrier (``carrier.render_target``), or ``None``."""
        self._hold_said = False
        if self.rendered is not None:  # the truth's target is the rendered body
            self.bodies.report_mass(mjcf.TARGET_BODY, tg.mass)
        self._contact, self._touching = self.contact_wrench()
        self._update_kinematics()
        self._post_args = (*self._mj, *self._tool_contact.kernel_args, self._qfrc_bias,
                           self._warn_number, self._qpos_arm, INERTIA_REUSE_RAD)
        self._fill = StateFill(self)
        self._state_ref: Callable[[], LazyArmState | None] = _no_state
        self._held: LazyArmState | None = None

        self.ft_model = FtSensorModel(
            scene.ft_sensor, self.rng, np.array([0.0, 0.0, -tool_tip_offset(scene)])
        )
        self.ft_read = False
        """An F/T sensor reads this world's samples (:class:`~drivers.world.ftstream.SimFtSensor`
        says so when made): a cycle stepped without them (:mod:`drivers.world.torque_step`)
        would starve it."""
        self._ft_decim = scene.ft_decimation
        self._ft_pending: list[FtSamples] = []
        self.cycle = 0
        self._step_count = 0
        self._ready = True

    # ------------------------------------------------------------------ setup
    def set_target_velocity(self, vx: float, vy: float, wz: float) -> None:
        """Give the air-bed target a twist in the bed plane (world frame) [m/s, rad/s]."""
        if not self._on_bed:
            raise ValueError("set_target_velocity is the air bed's planar twist; a free "
                             "target: bodies.set_free_twist")
        if self._ready:  # keep the end state of this cycle as it was
            state = self.last_state
            state.resolve()
            self._held = state
        v = self.data.qvel
        v[self._t_vadr[0]] = vx
        v[self._t_vadr[1]] = vy
        v[self._t_vadr[3]] = wz

    @property
    def jacobian(self) -> F64:
        """TCP Jacobian of the arm's joints at the current state, TCF rows (a copy)."""
        self._kinematics()
        return self._jfull[:, self._va].copy()

    @property
    def arm_qpos(self) -> F64:
        """The arm's joint positions now (a view into the state: do not modify)."""
        out: F64 = self._qpos_arm
        return out

    @property
    def arm_qvel(self) -> F64:
        """The arm's joint speeds now (a view into the state: do not modify)."""
        out: F64 = self._qvel_arm
        return out

    @property
    def mass_matrix(self) -> F64:
        """The arm's joint-space inertia at the current state (a copy)."""
        self._kinematics()
        return self._mfull[self._va, self._va].copy()

    def target_frames(self) -> tuple[F64, F64]:
        """The target block's pose and its funnel mouth's frame, 4x4 in the world
        frame at the current state (new arrays; what a tracker sees)."""
        d = self.data
        return (_pose(d.xpos[self._target_body], d.xmat[self._target_body]),
                _pose(d.site_xpos[self._mouth], d.site_xmat[self._mouth]))

    @property
    def tcp_pose(self) -> F64:
        """4x4 TCP pose in the base frame at the current state (do not modify)."""
        if not self._pose_ok:
            self._tcp_pose = (_pose(self._tcp_xpos, self._tcp_xmat) if self.chaser is None
                              else self.chaser.in_base(self._tcp_xpos, self._tcp_xmat))
            self._pose_ok = True
        return self._tcp_pose

    # -------------------------------------------------------------- per cycle
    def _kinematics(self) -> None:
        """Jacobian (TCF) and mass matrix of the current state, once per cycle (the TCP
        pose: :attr:`tcp_pose`)."""
        if self._kin_ok:
            return
        # mj_jacSite, [R^T jacp; R^T jacr] (the TCF rows), the mass matrix made and
        # factorised (once per end state) and mj_fullM, in one compiled call
        fns, m, d = self._mj
        self._tcf_kinematics(fns, m, d, self._tcp, self._jac2, self._tcp_rot, self._jfull2,
                             not self._m_ok, self._mfull)
        self._m_ok = self._kin_ok = True

    def _update_inertia(self) -> None:
        """Cartesian inertia (and the joint inertias) the KRC's damping uses, at this state."""
        # Lambda = (J M^-1 J^T)^-1 with MuJoCo's own factorisation of M (the Jacobian,
        # mass matrix and J M^-1 J^T in one compiled call; the inverse LAPACK's)
        fns, m, d = self._mj
        a = np.empty((6, 6))
        self._m_diag = np.empty(self._n)
        self._inertia_lhs(fns, m, d, self._tcp, self._jac2, self._tcp_rot, self._jfull2,
                          not self._kin_ok, not self._m_ok, self._mfull, self._jfull,
                          self._minv_jt, a, self._va.start, self._m_diag)
        self._kin_ok = self._m_ok = True
        lam = _inv(a)  # np.linalg.inv's own LAPACK gufunc; NaN: singular, let it raise
        self.cart_inertia = lam if lam[0, 0] == lam[0, 0] else np.linalg.inv(a)
        self._lam_diag = self.cart_inertia.diagonal().copy()
        self._inertia_new = True
        self._inertia_q = self._qpos_arm.copy()  # where it was computed

    def _update_kinematics(self) -> None:
        """Everything above at the current state, now."""
        self._kin_ok = self._pose_ok = False
        self._update_inertia()

    def _apply(self) -> None:
        """Write the held command into actuators, mocap and applied forces
        (:func:`drivers.world.actuate.apply`)."""
        apply(self)

    def _take(self, cmd: ArmCommand) -> None:
        """Latch the fields ``cmd`` gives (the others keep their values):
        :func:`drivers.world.latch.take`."""
        take(self, cmd)

    def step(self, command: ArmCommand | None = None) -> LazyArmState:
        """Latch ``command`` (``None``: keep everything), run one cycle, return its end state.

        The same as :meth:`advance` followed by :attr:`last_state`.

        Raises:
            InvalidCommandError: a given field is not finite or has the wrong
                shape; fields before it in :class:`ArmCommand` order were latched.
            SimulationError: the physics diverged during the cycle (the
                world's state is then not usable).
        """
        self.advance(command)
        return self.last_state

    @property
    def last_state(self) -> LazyArmState:
        """The state at the end of the last cycle (the start state before the first).

        Its fields are computed on first read (:mod:`drivers.world.state`: a
        cycle nobody reads costs no measurement, the Jacobian, mass matrix and
        truth only when read); the same object while someone holds it.
        """
        state = self._state_ref()
        if state is None:
            state = LazyArmState(self)
            self._state_ref = weakref.ref(state)
        return state

    def _let_go(self) -> None:
        """The data are about to change: a state still held gets its values now."""
        state = self._state_ref()
        if state is not None and state._world is not None:  # (else resolved already)
            state.resolve()
        self._state_ref = _no_state
        self._held = None

    def advance(self, command: ArmCommand | None = None) -> None:
        """Latch ``command`` and run one cycle, without building its :class:`ArmState`.

        What the cycle's end state needs is kept: the contact wrench of the
        last physics step, the F/T samples, and the kinematics, mass matrix and
        Cartesian inertia of the end state (the next cycle's damping needs them).

        Raises:
            InvalidCommandError, SimulationError: as :meth:`step`.
        """
        self._let_go()
        if command is not None:
            take(self, command)
        apply(self)
        if self.chaser is not None:  # the base's own control, and the wrench's frame
            self.chaser.cycle(self.tcp_pose)
        d = self.data
        self._friction.apply_into(self._qvel_arm, self._frictionloss)
        self._ft_steps.step()  # the cycle's physics steps, their sensor readings
        # Contacts and constraint forces are consistent now (state of the last
        # step, 1 physics step before the cycle's end): the tool's contact, then the
        # end state's dynamics, MuJoCo's bad-state counters and the inertia's reuse test
        # in one compiled call (kernels.post_step)
        if self.rendered is None:
            self._contact = contact = np.empty(6)
            flags = self._post_step(*self._post_args, d.contact.geom if d.ncon else _NO_GEOM,
                                    contact, self._inertia_q)
            self._touching = bool(flags & _TOUCHING)
        else:
            flags = self._rendered_post(d)
        self._m_ok = False
        if flags & _DIVERGED:
            check_divergence(d, self._warn_number)
        decim = self._ft_decim
        if decim == 1:
            self._ft_pending.append(
                self.ft_model.process(self._ft_raw, self.cycle * self.cycle_ns))
        else:
            first = (-self._step_count) % decim
            rows = self._ft_raw[first::decim]
            if rows.shape[0]:
                self._ft_pending.append(self.ft_model.process(
                    rows, self.cycle * self.cycle_ns + first * self.step_ns))
        self._step_count += self.substeps
        self.cycle += 1
        self._kin_ok = self._pose_ok = False
        if flags & _INERTIA:  # a joint moved more than INERTIA_REUSE_RAD
            self._update_inertia()
        hold = self.rendered.hold if self.rendered is not None else None
        if hold is not None and not self._hold_said:  # said once: the chaser's run stops
            self._hold_said = True
            raise SimulationError(f"{hold.device} held at {hold.t_s:.3f} s: {hold.cause}")

    def _rendered_post(self, d: mujoco.MjData) -> int:
        """:meth:`advance`'s compiled call's work with the carrier's loop on the mock-up
        (:mod:`drivers.world.rendered`) between the contact and the end state."""
        assert self.rendered is not None
        self._contact, self._touching = self._tool_contact.wrench()
        self.rendered.cycle(self.cycle, self._contact, d.site_xpos[self._tcp],
                            d.site_xmat[self._tcp].reshape(3, 3))
        self._end_state_dynamics()
        check_divergence(d, self._warn_number)
        moved = np.abs(self._qpos_arm - self._inertia_q) > INERTIA_REUSE_RAD
        return _INERTIA if moved.any() else 0

    def _end_state_dynamics(self) -> None:
        """Kinematics and bias forces of the end state (its mass matrix: :meth:`_kinematics`).

        The parts of ``mj_step1`` the measurement and the next cycle's command read,
        without collisions and constraints (the next ``mj_step`` redoes both), bit for
        bit; the mass matrix is built on first use from what ``mj_comPos`` left."""
        # mj_kinematics, mj_comPos, mj_comVel, mj_passive (qfrc_gravcomp), mj_rne, compiled
        self._end_state(*self._mj, self._qfrc_bias)
        self._m_ok = False

    def ft_samples(self) -> FtSamples:
        """Every F/T sample produced since the last call."""
        out = FtSamples.concat(self._ft_pending)
        self._ft_pending = []
        return out

    def tare_ft(self) -> None:
        """Software bias: the last sample reads zero from now on (Net F/T 0x0042)."""
        last = self.ft_model.last_wrench
        if last is not None:
            self.ft_model.tare_offset = self.ft_model.tare_offset + last

    # ------------------------------------------------------------ measurement
    def contact_wrench(self) -> tuple[F64, bool]:
        """The target's wrench on the tool and whether touching (:class:`ToolContact`)."""
        return self._tool_contact.wrench()

    @property
    def cycle_s(self) -> float:
        """The control cycle [s]."""
        return float(self.scene.fri.cycle)

    @property
    def time(self) -> float:
        """Simulated time since the start [s]."""
        return self.cycle * self.scene.fri.cycle
