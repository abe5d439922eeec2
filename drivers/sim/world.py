"""The simulated rig: LWR4+ with its KRC impedance controller, air-bed target, F/T sensor.

:class:`SimWorld` is a physics world only: ``step(command)`` latches an
:class:`~drivers.sim.arm.ArmCommand` (if given), runs one control cycle of
physics and returns the :class:`~drivers.sim.arm.ArmState` at its end. It
knows no link protocol: how FRI's flags select fields, when the link takes
commands (MON/CMD) and its quality are the emulator's (:mod:`drivers.emulate`).

How the KRC is modelled (see :mod:`drivers.sim.controller` for the laws):

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

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from drivers.base.types import F64, FtSamples, GroundTruth
from drivers.errors import ConfigError, InvalidCommandError, SimulationError
from drivers.sim import mjcf
from drivers.sim.arm import ArmCommand, ArmMode, ArmState, ArmWarning
from drivers.sim.controller import clip_cart_stiffness, normalized_damping
from drivers.sim.divergence import check_divergence, quiet_divergence
from drivers.sim.ftsensor import FtSensorModel
from drivers.sim.scene import Scene
from drivers.sim.truth import ground_truth
from drivers.sim.truth import pose as _pose

#: The KRC's damping uses the Cartesian inertia of the configuration where it was
#: last computed until a joint has moved this far from it [rad]. Measured pressing
#: into the funnel: 1 mrad keeps the damping within 0.06 % of the exact value
#: (3 mrad: 0.4 %; 10 mrad: off by up to 8x near a poorly conditioned axis).
INERTIA_REUSE_RAD = 1e-3
_N_ARM = 7
_YZX = np.array([1, 2, 0])
_ZXY = np.array([2, 0, 1])

_WARN_CLIPPED = int(ArmWarning.STIFFNESS_CLIPPED)
_WARN_TORQUE = int(ArmWarning.TORQUE_LIMIT)
_WARN_VELOCITY = int(ArmWarning.VELOCITY_LIMIT)
_WARN_POSITION = int(ArmWarning.POSITION_LIMIT)
_MODES = {
    "cart_impedance": ArmMode.CART_IMPEDANCE,
    "joint_position": ArmMode.JOINT_POSITION,
    "joint_impedance": ArmMode.JOINT_IMPEDANCE,
}


@dataclass(frozen=True)
class ContactInfo:
    """Funnel contact parameters as MuJoCo sees them (for the record)."""

    m_eff: float
    solref_stiffness: float
    solref_damping: float


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

        # 1. Arm alone: where is the TCF at the start pose?
        m0 = mujoco.MjModel.from_xml_string(mjcf.build_xml(scene, None))
        d0 = mujoco.MjData(m0)
        d0.qpos[:_N_ARM] = scene.arm.q_init
        mujoco.mj_forward(m0, d0)
        tcp0 = d0.site("tcp")
        self.layout = mjcf.compute_layout(scene, tcp0.xpos.copy(), tcp0.xmat.reshape(3, 3).copy())

        # 2. The whole rig.
        self.xml = mjcf.build_xml(scene, self.layout)
        self.model = m = mujoco.MjModel.from_xml_string(self.xml)
        self.data = d = mujoco.MjData(m)
        self._ready = False
        quiet_divergence(m, d)
        self._friction = scene.arm.joint_friction()
        self._friction.install(m)
        self._tcp = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "tcp")
        self._ft_site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "ft_site")
        self._mouth = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "funnel_mouth")
        cmd_body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "cmd_frame")
        self._cmd_mocap = int(m.body_mocapid[cmd_body])
        self._target_body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "target")
        self._tool_body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "tool")
        jid = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n) for n in mjcf.TARGET_JOINTS]
        self._t_qadr = np.array([m.jnt_qposadr[j] for j in jid])
        self._t_vadr = np.array([m.jnt_dofadr[j] for j in jid])
        self._t_twist_adr = self._t_vadr[[0, 1, 3]]
        self._tool_geoms = {g for g in range(m.ngeom) if m.geom_bodyid[g] == self._tool_body
                            and m.geom_contype[g] != 0}
        self._is_tool_geom = np.zeros(m.ngeom, dtype=bool)
        self._is_tool_geom[list(self._tool_geoms)] = True
        self._tool_root = int(m.body_rootid[self._tool_body])
        self._funnel_geoms = {
            g for g in range(m.ngeom)
            if m.geom_contype[g] != 0 and m.geom_bodyid[g] != self._target_body
            and (g in self._tool_geoms or m.geom_contype[g] == 2)
        }
        self._act_jnt = slice(0, 7)
        self._act_cart = slice(7, 13)
        self._act_ft = slice(13, 19)
        self._vel_limits = np.radians(mjcf.LWR_VEL_LIMITS_DEG)
        self._pos_limits = np.radians(mjcf.LWR_POS_LIMITS_DEG)
        self._torque_limits = np.asarray(scene.arm.torque_limits)
        self._pos_warn = self._pos_limits - 1e-3
        self._torque_warn = self._torque_limits - 1e-9

        # Preallocated work arrays.
        self._jacp = np.zeros((3, m.nv))
        self._jacr = np.zeros((3, m.nv))
        self._mfull = np.zeros((m.nv, m.nv))
        self._jfull = np.zeros((6, m.nv))
        self._minv_jt = np.zeros((6, m.nv))
        self._kin_ok = False
        self._inertia_q = np.zeros(_N_ARM)
        self._inertia_new = True
        # views into MuJoCo's buffers written every cycle
        self._cart_damp_prm = m.actuator_biasprm[self._act_cart, 2]
        self._bias_arm = d.qfrc_bias[:_N_ARM]
        self._gravcomp_arm = d.qfrc_gravcomp[:_N_ARM]
        self._applied_arm = d.qfrc_applied[:_N_ARM]
        self._ft_raw = np.zeros((self.substeps, 6))
        self._cforce = np.zeros(6)
        self._quat = np.zeros(4)
        self._sensordata = d.sensordata
        fadr = m.sensor_adr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, mjcf.FT_SENSOR_FORCE)]
        tadr = m.sensor_adr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, mjcf.FT_SENSOR_TORQUE)]
        if tadr != fadr + 3:
            raise SimulationError("unexpected sensor layout")
        self._ft_adr = int(fadr)

        # Start state: arm at q_init, target yawed on its hinge.
        d.qpos[self._t_qadr[3]] = self.layout.target_yaw
        d.qpos[:_N_ARM] = scene.arm.q_init
        mujoco.mj_forward(m, d)
        self._update_kinematics()

        # Funnel contact: physical N/m -> MuJoCo direct solref via the effective mass.
        self.contact_info = self._configure_contact()

        # Initial command: hold the start pose with the scene's impedance.
        self.mode = _MODES[scene.fri.control]
        ctl = scene.controller
        self._cart_pos = self.tcp_pose.copy()
        self._cart_stiff = np.asarray(ctl.cart_stiffness, dtype=np.float64)
        self._cart_damp = np.asarray(ctl.cart_damping, dtype=np.float64)
        self._tcp_ft = np.zeros(6)
        self._jnt_pos = d.qpos[:_N_ARM].copy()
        self._jnt_trq = np.zeros(7)
        self._jnt_stiff = np.full(7, ctl.jnt_position_stiffness)
        self._jnt_damp = np.full(7, ctl.jnt_position_damping)
        self._warning = 0
        self._latched = True
        self._apply()

        # Let the target settle on its pads, then start the clock.
        for _ in range(round(scene.physics.settle_time / self.dt)):
            mujoco.mj_step(m, d)
        self._check_divergence()
        d.time = 0.0
        vx, vy, wz = scene.target.velocity
        self.set_target_velocity(vx, vy, wz)
        mujoco.mj_forward(m, d)
        self._contact, self._touching = self.contact_wrench()
        self._update_kinematics()
        self._state: ArmState | None = None

        self.ft_model = FtSensorModel(
            scene.ft_sensor, self.rng, np.array([0.0, 0.0, -mjcf.tool_tip_offset(scene)])
        )
        self._ft_decim = scene.ft_decimation
        self._ft_pending: list[FtSamples] = []
        self.cycle = 0
        self._step_count = 0
        self._ready = True

    # ------------------------------------------------------------------ setup
    def _configure_contact(self) -> ContactInfo:
        """Map the scene's contact stiffness [N/m] and damping ratio onto solref.

        MuJoCo's direct solref is mass-normalised (fact sheet sec. 3): a
        contact with constant impedance d and reference stiffness k holds a
        quasi-static load F at penetration ``F (1 - d) / (d k m_eff)``. We pick
        k so that this equals ``F / stiffness``, with m_eff the reduced mass
        of the TCP (Cartesian inertia along the approach axis) and the target.
        """
        ct = self.scene.contact
        lam = self.cart_inertia
        m_tcp = float(lam[2, 2])
        m_eff = 1.0 / (1.0 / m_tcp + 1.0 / self.scene.target.mass)
        dimp = ct.impedance
        k = ct.stiffness * (1.0 - dimp) / (dimp * m_eff)
        limit = 1.0 / (2.0 * self.dt) ** 2
        if k > limit:
            raise ConfigError(
                self.scene.name, "contact.stiffness",
                f"{ct.stiffness:g} N/m maps to solref stiffness {k:.3g} > 1/(2h)^2 = {limit:.3g}; "
                "lower it or the physics timestep",
            )
        b = 2.0 * ct.damping_ratio * math.sqrt(dimp * k) / dimp
        m = self.model
        for g in self._funnel_geoms:
            m.geom_solref[g, 0] = -k
            m.geom_solref[g, 1] = -b
        return ContactInfo(m_eff=m_eff, solref_stiffness=k, solref_damping=b)

    def set_target_velocity(self, vx: float, vy: float, wz: float) -> None:
        """Give the target a twist in the bed plane (world frame) [m/s, rad/s]."""
        if self._ready:
            _ = self.last_state  # keep the end state of this cycle as it was
        v = self.data.qvel
        v[self._t_vadr[0]] = vx
        v[self._t_vadr[1]] = vy
        v[self._t_vadr[3]] = wz

    @property
    def jacobian(self) -> F64:
        """TCP Jacobian of the arm's joints at the current state, TCF rows (a copy)."""
        self._kinematics()
        return self._jfull[:, :_N_ARM].copy()

    @property
    def mass_matrix(self) -> F64:
        """The arm's joint-space inertia at the current state (a copy)."""
        self._kinematics()
        return self._mfull[:_N_ARM, :_N_ARM].copy()

    def target_frames(self) -> tuple[F64, F64]:
        """The target block's pose and its funnel mouth's frame, 4x4 in the world
        frame at the current state (new arrays; what a tracker sees)."""
        d = self.data
        return (_pose(d.xpos[self._target_body], d.xmat[self._target_body]),
                _pose(d.site_xpos[self._mouth], d.site_xmat[self._mouth]))

    @property
    def tcp_pose(self) -> F64:
        """4x4 TCP pose in the base frame at the current state (do not modify)."""
        self._kinematics()
        return self._tcp_pose

    # -------------------------------------------------------------- per cycle
    def _kinematics(self) -> None:
        """TCP pose, Jacobian (TCF) and mass matrix of the current state, once per cycle."""
        if self._kin_ok:
            return
        m, d = self.model, self.data
        self._tcp_pose = _pose(d.site_xpos[self._tcp], d.site_xmat[self._tcp])
        r = self._tcp_pose[:3, :3]
        mujoco.mj_jacSite(m, d, self._jacp, self._jacr, self._tcp)
        jfull = self._jfull
        np.matmul(r.T, self._jacp, out=jfull[:3])
        np.matmul(r.T, self._jacr, out=jfull[3:])
        mujoco.mj_fullM(m, d, self._mfull)
        self._kin_ok = True

    def _update_inertia(self) -> None:
        """Cartesian inertia (and the joint inertias) the KRC's damping uses, at this state."""
        self._kinematics()
        jfull = self._jfull
        # Lambda = (J M^-1 J^T)^-1 with MuJoCo's own factorisation of M.
        mujoco.mj_solveM(self.model, self.data, self._minv_jt, jfull)
        self.cart_inertia = np.linalg.inv(jfull @ self._minv_jt.T)
        self._lam_diag = np.diag(self.cart_inertia).copy()
        self._inertia_new = True
        self._m_diag = np.diag(self._mfull)[:_N_ARM].copy()
        self._inertia_q[:] = self.data.qpos[:_N_ARM]

    def _update_kinematics(self) -> None:
        """Everything above at the current state, now."""
        self._kin_ok = False
        self._update_inertia()

    def _apply(self) -> None:
        """Write the held command into actuators, mocap and applied forces."""
        m, d = self.model, self.data
        gain = m.actuator_gainprm
        bias = m.actuator_biasprm
        ctrl = d.ctrl
        cart = self._act_cart
        jnt = self._act_jnt
        if self.mode == ArmMode.CART_IMPEDANCE:
            if self._latched or self._inertia_new:  # the damping: its inputs changed
                self._inertia_new = False
                damp = normalized_damping(self._cart_stiff, self._cart_damp, self._lam_diag)
                np.negative(damp, out=self._cart_damp_prm)
            if self._latched:  # the rest changes only with a command
                self._latched = False
                d.mocap_pos[self._cmd_mocap] = self._cart_pos[:3, 3]
                mujoco.mju_mat2Quat(self._quat, self._cart_pos[:3, :3].ravel())
                d.mocap_quat[self._cmd_mocap] = self._quat
                bias[cart, 1] = -self._cart_stiff
                ctrl[self._act_ft] = self._tcp_ft
                gain[jnt, 0] = 0.0
                bias[jnt, 0] = self._jnt_trq
                bias[jnt, 1] = 0.0
                bias[jnt, 2] = 0.0
        else:
            self._latched = True
            self._inertia_new = True  # the Cartesian damping is rewritten on return
            bias[cart, 1] = 0.0
            bias[cart, 2] = 0.0
            ctrl[self._act_ft] = 0.0
            if self.mode == ArmMode.JOINT_POSITION:
                k = np.full(7, self.scene.controller.jnt_position_stiffness)
                dd = np.full(7, self.scene.controller.jnt_position_damping)
            else:
                k, dd = self._jnt_stiff, self._jnt_damp
            damp = normalized_damping(k, dd, self._m_diag)
            gain[jnt, 0] = k
            bias[jnt, 0] = self._jnt_trq
            bias[jnt, 1] = -k
            bias[jnt, 2] = -damp
            ctrl[jnt] = self._jnt_pos
        # f_dyn: Coriolis/centrifugal (gravity is compensated inside every step).
        np.subtract(self._bias_arm, self._gravcomp_arm, out=self._applied_arm)

    def _take(self, cmd: ArmCommand) -> None:
        """Latch the fields ``cmd`` gives (the others keep their values)."""
        self._latched = True
        if cmd.mode is not None and cmd.mode != self.mode:
            if cmd.mode not in (ArmMode.CART_IMPEDANCE, ArmMode.JOINT_POSITION,
                                ArmMode.JOINT_IMPEDANCE):
                raise InvalidCommandError(f"control mode {cmd.mode!r} not supported")
            self.mode = ArmMode(cmd.mode)
            self._cart_pos = self.tcp_pose.copy()
            self._jnt_pos = self.data.qpos[:_N_ARM].copy()
        self._warning = 0
        if cmd.cart_pose_m is not None:
            p = np.asarray(cmd.cart_pose_m, dtype=np.float64)
            if p.shape != (4, 4) or not np.isfinite(p).all():
                raise InvalidCommandError("cart_pos must be a finite 4x4 pose")
            self._cart_pos = p.copy()
        if cmd.cart_stiffness_npm_nmprad is not None:
            k = np.asarray(cmd.cart_stiffness_npm_nmprad, dtype=np.float64)
            if k.shape != (6,) or not np.isfinite(k).all():
                raise InvalidCommandError("cart_stiffness must be 6 finite values")
            mx = self.scene.controller.cart_stiffness_max
            self._cart_stiff, clipped = clip_cart_stiffness(k, mx[0], mx[1])
            if clipped:
                self._warning |= _WARN_CLIPPED
        if cmd.cart_damping_ratio is not None:
            self._cart_damp = np.clip(
                self._finite(cmd.cart_damping_ratio, 6, "cart_damping"), 0.0, 1.0)
        if cmd.tcp_wrench_n_nm is not None:
            self._tcp_ft = self._finite(cmd.tcp_wrench_n_nm, 6, "add_tcp_ft")
        if cmd.jnt_pos_rad is not None:
            self._jnt_pos = np.clip(self._finite(cmd.jnt_pos_rad, 7, "jnt_pos"),
                                    -self._pos_limits, self._pos_limits)
        if cmd.jnt_trq_nm is not None:
            self._jnt_trq = self._finite(cmd.jnt_trq_nm, 7, "add_jnt_trq")
        if cmd.jnt_stiffness_nmprad is not None:
            k = self._finite(cmd.jnt_stiffness_nmprad, 7, "jnt_stiffness")
            self._jnt_stiff = np.clip(k, 0.0, self.scene.controller.jnt_stiffness_max)
            if np.any(self._jnt_stiff != k):
                self._warning |= _WARN_CLIPPED
        if cmd.jnt_damping_ratio is not None:
            self._jnt_damp = np.clip(
                self._finite(cmd.jnt_damping_ratio, 7, "jnt_damping"), 0.0, 1.0)

    @staticmethod
    def _finite(v: F64, n: int, name: str) -> F64:
        a = np.asarray(v, dtype=np.float64)
        if a.shape != (n,) or not np.isfinite(a).all():
            raise InvalidCommandError(f"{name} must be {n} finite values")
        return a.copy()

    def _check_divergence(self) -> None:
        """Raise SimulationError if the physics diverged (:mod:`drivers.sim.divergence`)."""
        check_divergence(self.data)

    def step(self, command: ArmCommand | None = None) -> ArmState:
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
    def last_state(self) -> ArmState:
        """The state at the end of the last cycle (the start state before the first).

        Built on first access in a cycle and kept until the next one (a cycle
        nobody reads costs no measurement).
        """
        state = self._state
        if state is None:
            state = self._state = self._measure()
        return state

    def advance(self, command: ArmCommand | None = None) -> None:
        """Latch ``command`` and run one cycle, without building its :class:`ArmState`.

        What the cycle's end state needs is kept: the contact wrench of the
        last physics step, the F/T samples, and the kinematics, mass matrix and
        Cartesian inertia of the end state (the next cycle's damping needs them).

        Raises:
            InvalidCommandError, SimulationError: as :meth:`step`.
        """
        if command is not None:
            self._take(command)
        self._state = None
        self._apply()
        m, d = self.model, self.data
        self._friction.apply(m, d.qvel)
        raw = self._ft_raw
        sd = self._sensordata
        a = self._ft_adr
        step = mujoco.mj_step
        for i in range(self.substeps):
            step(m, d)
            raw[i] = sd[a:a + 6]
        # Contacts and constraint forces are consistent now (state of the last
        # step, 1 physics step before the cycle's end).
        self._contact, self._touching = self.contact_wrench()
        self._end_state_dynamics()
        self._check_divergence()
        t0 = self.cycle * self.cycle_ns
        first = (-self._step_count) % self._ft_decim
        rows = raw[first::self._ft_decim]
        if rows.shape[0]:
            self._ft_pending.append(self.ft_model.process(rows, t0 + first * self.step_ns))
        self._step_count += self.substeps
        self.cycle += 1
        self._kin_ok = False
        q = d.qpos[:_N_ARM]
        if np.abs(q - self._inertia_q).max() > INERTIA_REUSE_RAD:
            self._update_inertia()

    def _end_state_dynamics(self) -> None:
        """Kinematics, mass matrix (factorised) and bias forces of the end state.

        The parts of ``mj_step1`` the measurement and the next cycle's command
        read, without its collision detection and constraint set-up (the next
        ``mj_step`` redoes both); the values are bit-identical to ``mj_step1``'s.
        """
        m, d = self.model, self.data
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        mujoco.mj_makeM(m, d)
        mujoco.mj_factorM(m, d)
        mujoco.mj_comVel(m, d)
        mujoco.mj_passive(m, d)  # qfrc_gravcomp
        mujoco.mj_rne(m, d, 0, d.qfrc_bias)

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
        """True wrench the target exerts on the tool (TCF at the TCP), and whether touching.

        Valid only right after ``mj_step``/``mj_forward`` (contacts and
        constraint forces must come from the same collision pass). Touching:
        a tool geom is in the contact list (within the margin counts). The
        wrench is the tool body's external force from MuJoCo's
        ``mj_rnePostConstraint`` (the sum of its contacts' forces, which only
        the target funnel makes: the contype convention), moved from the
        subtree centre of mass to the TCP.
        """
        m, d = self.model, self.data
        if d.ncon == 0:
            return np.zeros(6), False
        if not self._is_tool_geom[d.contact.geom].any():
            return np.zeros(6), False
        mujoco.mj_rnePostConstraint(m, d)
        cfrc = d.cfrc_ext[self._tool_body]  # [torque about the subtree com, force], world
        f = cfrc[3:]
        r = d.subtree_com[self._tool_root] - d.site_xpos[self._tcp]
        torque = cfrc[:3] + r[_YZX] * f[_ZXY] - r[_ZXY] * f[_YZX]  # + r x f
        rot = d.site_xmat[self._tcp].reshape(3, 3)
        out = np.empty(6)
        out[:3] = f @ rot
        out[3:] = torque @ rot
        return out, True

    def _truth(self, contact: F64, touching: bool, tcp_twist: F64) -> GroundTruth:
        d = self.data
        return ground_truth(
            _pose(d.xpos[self._target_body], d.xmat[self._target_body]),
            d.qvel[self._t_twist_adr], self.tcp_pose, d.site_xpos[self._mouth],
            d.site_xmat[self._mouth], self.layout.funnel_seat_depth, contact, touching, tcp_twist,
        )

    def _measure(self) -> ArmState:
        d = self.data
        q = d.qpos[:_N_ARM].copy()
        qd = d.qvel[:_N_ARM]
        jac = self.jacobian
        mass = self.mass_matrix
        contact, touching = self._contact, self._touching
        tau_ext = jac.T @ contact
        gravity = d.qfrc_gravcomp[:_N_ARM].copy()
        # Link-side torque sensors: M qdd + c + g = tau_msr + tau_ext.
        tau_msr = mass @ d.qacc[:_N_ARM] + d.qfrc_bias[:_N_ARM] - tau_ext
        warning = self._warning
        if (np.abs(qd) > self._vel_limits).any():
            warning |= _WARN_VELOCITY
        if (np.abs(q) > self._pos_warn).any():
            warning |= _WARN_POSITION
        if (np.abs(d.qfrc_actuator[:_N_ARM]) >= self._torque_warn).any():
            warning |= _WARN_TORQUE
        cart = self.mode == ArmMode.CART_IMPEDANCE
        tcp_twist = jac @ qd
        return ArmState(
            cycle=self.cycle,
            time_ns=self.cycle * self.cycle_ns,
            mode=self.mode,
            jnt_pos_rad=q,
            tcp_pose_m=self.tcp_pose,
            cmd_jnt_pos_rad=q.copy() if cart else self._jnt_pos.copy(),
            cmd_cart_pose_m=self._cart_pos.copy() if cart else self.tcp_pose.copy(),
            jnt_trq_nm=tau_msr,
            ext_jnt_trq_nm=tau_ext,
            ext_wrench_n_nm=contact.copy(),
            jacobian=jac,
            mass_matrix=mass,
            gravity_nm=gravity,
            warning=ArmWarning(warning),
            truth=self._truth(contact, touching, tcp_twist),
        )

    @property
    def cycle_s(self) -> float:
        """The control cycle [s]."""
        return float(self.scene.fri.cycle)

    @property
    def time(self) -> float:
        """Simulated time since the start [s]."""
        return self.cycle * self.scene.fri.cycle
