"""The world's arm stepped in its joint modes only, lean: a 1 kHz torque interface's cycle.

:class:`SimWorld.advance <drivers.world.world.SimWorld.advance>` runs a control cycle for
every reader the KRC's Cartesian impedance has: the F/T sensor's samples (noise drawn
from the world's generator), the Cartesian inertia behind the damping, the end state's
dynamics computed apart from the next step's. A controller that only ever commands the
joint modes (a joint position servo, or joint impedance with a joint torque on top: a
Franka's torque loop) and has no F/T sensor needs none of them. :class:`TorqueStepper`
runs such a world's cycle with the same physics, bit for bit (the same MuJoCo calls on
the same inputs; ``tests/test_franka_torque_step.py`` checks ``qpos``, ``qvel`` and the
reported state against ``SimWorld.advance``), and less work:

* the physics step split where MuJoCo allows it (``mj_step1``, the parts that need only
  positions and velocities; ``mj_step2``, the rest): a cycle ends with the next step's
  ``mj_step1``, whose kinematics, mass matrix and bias forces are the end state the
  reader wants, so they are computed once, not once for the state and again inside the
  next ``mj_step``;
* the model's sensors disabled (only the F/T sensor reads, and its samples have no
  reader here: the generator is not drawn from; the world's F/T samples stop); the
  tool's contact wrench comes from
  :class:`~drivers.world.contact.ToolContact`, which computes the body forces itself
  when the tool touches;
* the actuators written only when what they hold changes (a mode, a set-point, a
  torque, the joint inertia the servo's damping uses), not every cycle;
* the mass matrix's joint block read straight from MuJoCo's sparse ``M`` (the values
  ``mj_fullM`` copies), the Jacobian only while the tool touches (without contact the
  external torques are zero).

The world keeps answering its readers: :attr:`SimWorld.last_state
<drivers.world.world.SimWorld.last_state>` (its truth included) is the end state of the
last cycle run here, :attr:`~drivers.world.world.SimWorld.cycle` and ``time`` count
them. What a world with a moving base or a rendered target needs is not done here:
:func:`unfit` says why such a world must be stepped by ``SimWorld.advance``. Once a
world is stepped here, it is stepped here only (its Cartesian inertia and F/T sensor
are left as they were). Positions or velocities set between cycles (a target's
velocity given) are seen: the step's first stage is run again at them.

The few places this reaches into :class:`~drivers.world.world.SimWorld`'s own
bookkeeping (the latched joint set-point and mode its state reports, its cache flags)
are the attributes named in :data:`WORLD_FIELDS`, checked when a stepper is made.
"""

from __future__ import annotations

from typing import Final

import mujoco
import numpy as np

from drivers.base.impedance import normalized_damping
from drivers.base.types import F64
from drivers.errors import InvalidCommandError
from drivers.world.arm import ArmCommand, ArmMode
from drivers.world.contact import ToolContact
from drivers.world.divergence import check_divergence
from drivers.world.friction import JointFriction
from drivers.world.latch import take
from drivers.world.world import INERTIA_REUSE_RAD, SimWorld

__all__ = ["WORLD_FIELDS", "TorqueStepper", "unfit"]

#: :class:`SimWorld`'s own attributes a stepper reads or keeps current (what its
#: ``last_state`` reports from: the mode, the joint set-point, the warning bits, the
#: contact; the flags of its per-cycle caches; where its joint inertia was taken).
WORLD_FIELDS: Final = ("mode", "_jnt_pos", "_jnt_trq", "_jnt_stiff", "_jnt_damp", "_cart_pos",
                       "_warning", "_contact", "_touching", "_kin_ok", "_pose_ok", "_m_ok",
                       "_m_diag", "_inertia_q", "_let_go", "_qa", "_va")

_JOINT_MODES = (ArmMode.JOINT_POSITION, ArmMode.JOINT_IMPEDANCE)
#: The contact wrench of a cycle without contact (shared by all of them: read-only).
_NO_CONTACT = np.zeros(6)
_NO_CONTACT.flags.writeable = False


def unfit(world: SimWorld) -> str | None:
    """Why ``world`` cannot be stepped by a :class:`TorqueStepper` (``None``: it can)."""
    if world.chaser is not None:
        return "a floating base (its own control every cycle)"
    if world.rendered is not None:
        return "a rendered target (its carrier's loop every cycle)"
    if world.ft_read:
        return "an F/T sensor reads its samples (drawn only by SimWorld.advance)"
    missing = [name for name in WORLD_FIELDS if not hasattr(world, name)]
    if missing:
        return f"a SimWorld without {', '.join(missing)}"
    return None


class TorqueStepper:
    """``world``'s cycle in its joint modes (module docstring).

    Raises:
        ValueError: ``world`` is unfit for it (:func:`unfit` names why).
    """

    def __init__(self, world: SimWorld) -> None:
        why = unfit(world)
        if why is not None:
            raise ValueError(f"the world cannot be stepped lean: {why}")
        self.world = w = world
        self.model = m = world.model
        self.data = d = world.data
        self.substeps = world.substeps
        n = self._n = world.scene.arm.description.joints
        qa, va = w._qa, w._va
        ctl = world.scene.controller
        self._position_k = np.full(n, ctl.jnt_position_stiffness)
        self._position_d = np.full(n, ctl.jnt_position_damping)
        # the actuators: the arm's joints first, then six Cartesian, then six wrench ones
        gain, bias = m.actuator_gainprm, m.actuator_biasprm
        self._gain_k = gain[:n, 0]
        self._bias_trq = bias[:n, 0]
        self._bias_k = bias[:n, 1]
        self._bias_d = bias[:n, 2]
        self._bias_cart = bias[n:n + 6, 1:3]
        self._ctrl_jnt = d.ctrl[:n]
        self._ctrl_ft = d.ctrl[n + 6:n + 12]
        # views into the state (MuJoCo's arrays stay where they are for the data's life)
        self.qpos = d.qpos[qa]
        """The arm's joint positions (a view: do not modify)."""
        self.qvel = d.qvel[va]
        """The arm's joint speeds (a view: do not modify)."""
        tcp = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "tcp")
        self.tcp_xpos = d.site_xpos[tcp]
        """The TCP's position (world frame, a view)."""
        self.tcp_xmat = d.site_xmat[tcp]
        """The TCP's orientation, row-major 3x3 (a view)."""
        self._tcp = tcp
        self._qpos_all, self._qvel_all = d.qpos, d.qvel
        self._qacc = d.qacc[va]
        self._m_sparse = d.M
        self._bias_arm = d.qfrc_bias[va]
        self._gravcomp_arm = d.qfrc_gravcomp[va]
        self._applied_arm = d.qfrc_applied[va]
        self._frictionloss = m.dof_frictionloss[va]
        self._friction = JointFriction.of_arm(world.scene.arm)
        self._warn_number = d.warning.number
        self._warn_quiet = self._warn_number.tolist()  # primed: quiet_divergence
        tool = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "tool")
        self._tool_geoms = frozenset(g for g in range(m.ngeom)
                                     if m.geom_bodyid[g] == tool and m.geom_contype[g] != 0)
        self._tool_contact = ToolContact(m, d, tool, set(self._tool_geoms), tcp)
        # the arm's block of the mass matrix: where each (i, j) is in MuJoCo's sparse
        # lower triangle ``M`` (rows of ``M_rownnz`` values from ``M_rowadr``, their
        # columns in ``M_colind``); the arm is a chain, so the block is full
        idx = np.full((n, n), -1, dtype=np.intp)
        for i in range(n):
            row = int(m.M_rowadr[va.start + i])
            for k in range(row, row + int(m.M_rownnz[va.start + i])):
                j = int(m.M_colind[k]) - va.start
                if 0 <= j < n:
                    idx[i, j] = idx[j, i] = k
        if (idx < 0).any():
            raise ValueError("the world cannot be stepped lean: its arm's mass matrix "
                             "has structural zeros (not a chain)")
        self._m_idx = idx.ravel()
        self._m_diag_idx = idx.diagonal().copy()
        self._mass = np.zeros((n, n))
        self._mass_flat = self._mass.reshape(-1)
        self._m_qdd = np.zeros(n)
        self._no_tau_ext = np.zeros(n)
        self._no_tau_ext.flags.writeable = False
        self.tau_ext: F64 = self._no_tau_ext
        """The external joint torques at the end state (:meth:`torques`; while the tool
        touches nothing, the same read-only zeros)."""
        self._jac2 = np.zeros((2, 3, m.nv))
        self._jfull = np.zeros((6, m.nv))
        self._jfull2 = self._jfull.reshape(2, 3, m.nv)
        self._va = va
        # the joint inertia the position servo's damping uses, and where it was taken
        self._m_diag: F64 = w._m_diag
        self._inertia_ql: list[float] = w._inertia_q.tolist()
        self._dirty = True  # what the world latched is not in the actuators yet
        self._gains_of: tuple[object, ...] = ()
        self._trq_written: F64 | None = None
        self._pos_written: F64 | None = None
        self.touching: bool = w._touching
        """The tool touches something at the end state."""
        self.contact: F64 = w._contact
        """The wrench the environment exerts on the tool, TCF at the TCP [N, N m]."""
        self._started = False
        self._seen = (b"", b"")
        self.q_list: list[float] = self.qpos.tolist()
        """The arm's joint positions at the end state, plain floats."""

    # ------------------------------------------------------------ commands
    def command(self, mode: ArmMode | None = None, jnt_pos_rad: F64 | None = None,
                jnt_trq_nm: F64 | None = None, jnt_stiffness_nmprad: F64 | None = None,
                jnt_damping_ratio: F64 | None = None) -> None:
        """Latch the fields given, as :class:`~drivers.world.arm.ArmCommand`'s are (a mode
        other than the running one first puts both set-points where the arm is; the
        others keep their values), in a joint mode.

        Raises:
            InvalidCommandError: a Cartesian mode, or a field not finite or of the wrong
                shape (the fields before it were latched).
        """
        w = self.world
        self._dirty = True
        if mode is not None and mode not in _JOINT_MODES:
            raise InvalidCommandError(f"control mode {mode!r}: joint modes only here")
        _joint_mode(w.mode if mode is None else mode)
        take(w, ArmCommand(mode=mode, jnt_pos_rad=jnt_pos_rad, jnt_trq_nm=jnt_trq_nm,
                           jnt_stiffness_nmprad=jnt_stiffness_nmprad,
                           jnt_damping_ratio=jnt_damping_ratio))

    def torque(self, jnt_trq_nm: F64) -> None:
        """Latch the joint torques only, into the actuators now: ``jnt_trq_nm`` is kept as
        it is (the caller gives an array of finite values it does not change afterwards)."""
        w = self.world
        self._bias_trq[...] = jnt_trq_nm
        w._jnt_trq = self._trq_written = jnt_trq_nm
        w._warning = 0

    # ------------------------------------------------------------ the cycle
    def _write_actuators(self) -> None:
        """The joint actuators from the world's latched mode, gains and set-points (what
        ``SimWorld``'s joint modes write), each only when it changed."""
        w = self.world
        if w.mode == ArmMode.JOINT_POSITION:
            k, dd = self._position_k, self._position_d
        else:
            k, dd = w._jnt_stiff, w._jnt_damp
        gains = (k, dd, self._m_diag)
        if len(self._gains_of) != 3 or any(
                a is not b for a, b in zip(self._gains_of, gains, strict=True)):
            damp = normalized_damping(k, dd, self._m_diag)
            self._bias_cart[...] = 0.0
            self._ctrl_ft[...] = 0.0
            self._gain_k[...] = k
            self._bias_k[...] = -k
            self._bias_d[...] = -damp
            self._gains_of = gains
        if w._jnt_trq is not self._trq_written:
            self._bias_trq[...] = w._jnt_trq
            self._trq_written = w._jnt_trq
        if w._jnt_pos is not self._pos_written:
            self._ctrl_jnt[...] = w._jnt_pos
            self._pos_written = w._jnt_pos
        self._dirty = False

    def _stage1(self) -> None:
        """The coming step's first stage at the current state: the friction's level from
        the joint speeds, then ``mj_step1``; what it saw is kept (:meth:`advance` checks
        it)."""
        self._friction.apply_into(self.qvel, self._frictionloss)
        mujoco.mj_step1(self.model, self.data)
        self._seen = (self._qpos_all.tobytes(), self._qvel_all.tobytes())

    def advance(self) -> None:
        """One control cycle with what is latched.

        Raises:
            InvalidCommandError: the world is not in a joint mode.
            SimulationError: the physics diverged during the cycle.
        """
        w = self.world
        w._let_go()
        if not self._started:
            _joint_mode(w.mode)
            self.model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_SENSOR)
            self._stage1()
            np.subtract(self._bias_arm, self._gravcomp_arm, out=self._applied_arm)
            self._started = True
        elif (self._qvel_all.tobytes() != self._seen[1]
              or self._qpos_all.tobytes() != self._seen[0]):
            # positions or velocities set since (a target's velocity given between
            # cycles): the stage again, at the state as it is now; the applied forces
            # stay the cycle's start's, as SimWorld.advance's do
            self._stage1()
        if self._dirty:
            self._write_actuators()
        m, d = self.model, self.data
        mujoco.mj_step2(m, d)
        for _ in range(self.substeps - 1):  # the cycle's other physics steps
            mujoco.mj_step1(m, d)
            mujoco.mj_step2(m, d)
        # the contacts and constraint forces of the last step (collision is redone below):
        # a tool geom in the contact list (ToolContact's test), then its wrench
        if d.ncon and not self._tool_geoms.isdisjoint(d.contact.geom.ravel().tolist()):
            self.contact, self.touching = self._tool_contact.wrench()
        else:
            self.contact, self.touching = _NO_CONTACT, False
        w._contact, w._touching = self.contact, self.touching
        # the next cycle's first stage: the end state's kinematics, mass matrix and bias
        self._stage1()
        np.subtract(self._bias_arm, self._gravcomp_arm, out=self._applied_arm)
        warnings = self._warn_number.tolist()
        if warnings != self._warn_quiet:  # MuJoCo warned: a bad state raises
            check_divergence(d, self._warn_number)
            self._warn_quiet = warnings  # another warning, counted: not a divergence
        w.cycle += 1
        w._kin_ok = w._pose_ok = w._m_ok = False
        self.q_list = ql = self.qpos.tolist()
        for qi, q0 in zip(ql, self._inertia_ql, strict=True):
            if abs(qi - q0) > INERTIA_REUSE_RAD:  # the joint inertia the damping uses
                self._m_diag = self._m_sparse[self._m_diag_idx]
                self._inertia_ql = ql
                self._dirty = True
                break

    # ------------------------------------------------------------ the end state
    def torques(self, tau_j: np.ndarray) -> None:
        """The link-side torque sensors ``M qdd + c + g - tau_ext`` at the end state into
        ``tau_j`` (seven values, computed in float64, cast to its type as they are
        stored), and :attr:`tau_ext`, the external torques ``J^T w`` (TCF)."""
        self._m_sparse.take(self._m_idx, out=self._mass_flat)
        m_qdd = self._m_qdd
        np.matmul(self._mass, self._qacc, out=m_qdd)
        if not self.touching:
            self.tau_ext = self._no_tau_ext
            np.add(m_qdd, self._bias_arm, out=tau_j)
            return
        mujoco.mj_jacSite(self.model, self.data, self._jac2[0], self._jac2[1], self._tcp)
        np.matmul(self.tcp_xmat.reshape(3, 3).T, self._jac2, out=self._jfull2)
        jac = self._jfull[:, self._va].copy()
        self.tau_ext = jac.T @ self.contact
        m_qdd += self._bias_arm
        m_qdd -= self.tau_ext
        tau_j[...] = m_qdd


def _joint_mode(mode: ArmMode) -> None:
    if mode not in _JOINT_MODES:
        raise InvalidCommandError(f"a joint mode first: the world is in {ArmMode(mode).name}")

