"""The FR3's controller on the simulated world: libfranka's torque interface, 1 kHz.

Per millisecond the controller reports a ``RobotState`` (:data:`drivers.franka.codec.ROBOT_STATE`,
float32 as on the wire) and takes one ``RobotCommand``. While a motion with the external
controller runs, the world's arm gets the commanded joint torques (``tau_J_d``, gravity
excluded: the FR3 compensates gravity itself, as the world does inside every step) for the
next millisecond; a motion with the robot's own joint impedance controller and a joint
position (or velocity) generator follows the commanded joints (``q_c``, or ``dq_c``
integrated) with the world's joint position servo (franky's joint motions); otherwise the
joints are held where they are (the brakes' role). A cycle
whose command did not come (or came for another state) keeps the last torque and counts
against ``control_command_success_rate``, the fraction of the last 100 cycles answered,
as the robot reports it.

Reflexes (the robot's own safety): a joint at its position limit, beyond its speed limit,
or a commanded torque beyond its range ends the motion: ``robot_mode`` REFLEX, the error
named in ``errors`` and ``reflex_reason``, the arm held, and the motion's answer
``REFLEX_ABORTED`` (:attr:`Fr3SimController.ended`). :meth:`Fr3SimController.inject_reflex`
raises one on purpose (a fault: ``cartesian_reflex``, what a collision gives).
"""

from __future__ import annotations

import operator
from collections import deque
from typing import Final

import numpy as np

from drivers.base.types import F64
from drivers.description import tool_tip_offset
from drivers.franka import codec
from drivers.world.arm import ArmCommand, ArmMode
from drivers.world.state import LazyArmState
from drivers.world.torque_step import TorqueStepper, unfit
from drivers.world.world import SimWorld

__all__ = ["WINDOW", "Fr3SimController", "flange_to_tcp"]

#: Cycles ``control_command_success_rate`` is taken over.
WINDOW: Final = 100
_GRAVITY: Final = (0.0, 0.0, -9.81)
_le, _ge, _gt = operator.le, operator.ge, operator.gt


def flange_to_tcp(world: SimWorld) -> F64:
    """The scene's tool from the flange to the TCP (the sensor, then the tool's tip; the
    TCF turned half a turn about z, as the world mounts it): libfranka's ``F_T_EE``."""
    t = np.eye(4)
    t[:3, :3] = np.diag([-1.0, -1.0, 1.0])
    t[2, 3] = world.scene.tool.sensor_height + tool_tip_offset(world.scene)
    return t


class Fr3SimController:
    """The FR3's controller on ``world`` (module docstring).

    ``lean``: the world stepped through :class:`~drivers.world.torque_step.TorqueStepper`
    where it can be (:func:`~drivers.world.torque_step.unfit`), the same physics with less
    work; ``False``: through ``SimWorld.advance`` always. Which one is decided at the
    first cycle or state asked for, not here: an F/T sensor made on the world after the
    controller (the ``franka-sim`` robot's ``[ft] type = "sim"``) reads the world's
    samples, which only ``SimWorld.advance`` draws."""

    def __init__(self, world: SimWorld, lean: bool = True) -> None:
        self.world = world
        desc = world.scene.arm.description
        # the limits as plain floats, compared value by value
        self._lower: list[float] = np.radians(desc.lower_limits_deg).tolist()
        self._upper: list[float] = np.radians(desc.position_limits_deg).tolist()
        self._speed: list[float] = np.radians(desc.velocity_limits_degps).tolist()
        self._tau_max = [float(x) for x in world.scene.arm.torque_limits]
        self.message_id = 1
        self.moving = False
        """A motion with the external controller runs (libfranka's torque loop)."""
        self.ended: codec.MoveStatus | None = None
        """How the last motion ended, until it is reported (then ``None``)."""
        self.reflex: list[str] = []
        """The errors of the reflex in force (empty: none)."""
        self._answers: deque[bool] = deque([True] * WINDOW, maxlen=WINDOW)
        self._answered = WINDOW  # how many of ``_answers`` are True
        self._tau = np.zeros(desc.joints)
        self._generator = codec.MotionGeneratorMode.JOINT_VELOCITY
        self._controller = codec.ControllerMode.EXTERNAL_CONTROLLER
        self._external = True  # the controller is the external one (the torque loop)
        self._q_d = world.arm_qpos.copy()
        self._dq_d = np.zeros(desc.joints)
        self._holding = False  # the arm held where it stopped (the position servo latched)
        self._latched_external = False  # the world holds the torque loop's mode and gains
        self._f_t_ee = flange_to_tcp(world)
        self._zeros = np.zeros(desc.joints)  # never changed
        self._state = np.zeros((), dtype=codec.ROBOT_STATE)
        self._fill_constants()
        self._views = _StateViews(self._state)
        # what the record holds: the modes and flags of (moving, generator, controller,
        # reflex), the commanded joints and torques (the objects last written)
        self._modes_of: tuple[object, ...] = ()
        self._q_d_written: F64 | None = self._zeros
        self._tau_written: F64 | None = None
        self._answered_written = -1
        self._measured_at = -1  # the step whose end state the measured fields hold
        self._wrench_o = np.zeros(6)
        self._held_state: LazyArmState | None = None  # (_measured_world)
        self._wrench_written = True  # the record's wrench fields may be nonzero
        self._want_lean = lean
        self._lean: TorqueStepper | None = None
        self._decided = False  # lean or not: at the first step() or state() (_decide)
        self.steps = 0

    @property
    def lean(self) -> TorqueStepper | None:
        """What steps the world lean (``None``: ``SimWorld.advance`` does)."""
        if not self._decided:
            self._decide()
        return self._lean

    def _decide(self) -> None:
        """Lean or not, once: lean if asked for and the world is fit for it now."""
        self._decided = True
        if self._want_lean and unfit(self.world) is None:
            self._lean = TorqueStepper(self.world)

    @property
    def success_rate(self) -> float:
        """The fraction of the last :data:`WINDOW` cycles answered."""
        return self._answered / WINDOW

    # ------------------------------------------------------------ motion
    def start_motion(self, generator: codec.MoveMotionGeneratorMode =
                     codec.MoveMotionGeneratorMode.JOINT_VELOCITY,
                     controller: codec.MoveControllerMode =
                     codec.MoveControllerMode.EXTERNAL_CONTROLLER) -> codec.MoveStatus:
        """A Move: with the external controller (the motion generator the client names is
        reported, its commands not followed), or with the robot's own controller and a
        joint position or velocity generator; refused while a reflex is in force, or for
        a Cartesian generator without the external controller (not emulated)."""
        if self.reflex:
            return codec.MoveStatus.COMMAND_REJECTED_DUE_TO_ACTIVATED_SAFETY_FUNCTIONS
        external = controller == codec.MoveControllerMode.EXTERNAL_CONTROLLER
        if not external and generator not in (codec.MoveMotionGeneratorMode.JOINT_POSITION,
                                              codec.MoveMotionGeneratorMode.JOINT_VELOCITY):
            return codec.MoveStatus.COMMAND_NOT_POSSIBLE_REJECTED
        self._generator = codec.MotionGeneratorMode(int(generator) + 1)
        self._controller = codec.ControllerMode(int(controller))
        self._external = external
        self._q_d = self.world.arm_qpos.copy()
        self._dq_d = np.zeros_like(self._q_d)
        self.moving, self.ended = True, None
        self._tau = np.zeros_like(self._tau)
        self._holding = False
        self._latched_external = False
        return codec.MoveStatus.MOTION_STARTED

    def finish_motion(self, status: codec.MoveStatus = codec.MoveStatus.SUCCESS) -> None:
        """End the motion (the client finished it, or a stop)."""
        if self.moving:
            self.moving, self.ended = False, status

    def recover(self) -> None:
        """Automatic error recovery: the reflex is cleared."""
        self.reflex = []

    def inject_reflex(self, name: str = "cartesian_reflex") -> None:
        """A reflex now (a fault), as a collision would give."""
        self._reflex([name])

    def _reflex(self, names: list[str]) -> None:
        self.reflex = names
        self.finish_motion(codec.MoveStatus.REFLEX_ABORTED)

    # ------------------------------------------------------------ the cycle
    def step(self, command: np.void | None) -> None:
        """One millisecond: take ``command`` (a :data:`~drivers.franka.codec.ROBOT_COMMAND`
        for the current state, or ``None``: none came), run the world, check the limits.

        The command's id, torques and end flags are read in one unpacking
        (:data:`~drivers.franka.codec.COMMAND_TORQUES`), the limits compared value by
        value (plain floats: seven joints)."""
        if not self._decided:
            self._decide()
        moving = self.moving
        fields = None if command is None else codec.COMMAND_TORQUES.unpack_from(command)  # type: ignore[arg-type]
        answered = fields is not None and fields[0] == self.message_id
        if moving:
            self._answered += answered - self._answers[0]  # the oldest leaves the window
            self._answers.append(answered)
        external = self._external
        if answered and moving:
            assert command is not None and fields is not None
            if not external:
                if self._generator == codec.MotionGeneratorMode.JOINT_POSITION:
                    q_c = np.array(command["q_c"], dtype=np.float64)  # copies: kept
                    self._dq_d = (q_c - self._q_d) / self.world.cycle_s
                    self._q_d = q_c
                else:
                    self._dq_d = np.array(command["dq_c"], dtype=np.float64)
                    self._q_d = self._q_d + self._dq_d * self.world.cycle_s
            else:
                tau = fields[2:9]
                # |tau| within the range (not finite: the comparison fails too)
                if all(map(_le, map(abs, tau), self._tau_max)):
                    self._tau = np.array(tau)  # kept: the record's view may change
                else:
                    self._reflex(["tau_j_range_violation"])
            if fields[1] or fields[9]:  # motion_generation_ or torque_command_finished
                self.finish_motion()
        if self._lean is not None:
            self._advance_lean(external)
            # the measured fields of the next state now, while the step's data are in the
            # cache (a cycle begins after a sleep in which other processes ran)
            self._measured_lean(self._views)
            self._measured_at = self.steps + 1
        else:
            self._advance_world(external)
        self.steps += 1
        self.message_id += 1
        if self.moving:
            w = self.world
            q = w.arm_qpos.tolist() if self._lean is None else self._lean.q_list
            names = []
            if any(map(_le, q, self._lower)) or any(map(_ge, q, self._upper)):
                names.append("joint_position_limits_violation")
            if any(map(_gt, map(abs, w.arm_qvel.tolist()), self._speed)):
                names.append("joint_velocity_violation")
            if names:
                self._reflex(names)

    def _advance_lean(self, external: bool) -> None:
        """The world's cycle through its lean joint-mode path (:mod:`drivers.world.torque_step`)."""
        lean = self._lean
        assert lean is not None
        if self.moving and not external:
            lean.command(ArmMode.JOINT_POSITION, jnt_pos_rad=self._q_d, jnt_trq_nm=self._zeros)
            self._latched_external = False
        elif self.moving:
            if self._latched_external:  # the mode and zero gains stay latched in the world
                lean.torque(self._tau)
            else:
                lean.command(ArmMode.JOINT_IMPEDANCE, jnt_stiffness_nmprad=self._zeros,
                             jnt_damping_ratio=self._zeros, jnt_trq_nm=self._tau)
                self._latched_external = True
        else:
            self._latched_external = False
            if not self._holding:
                self._holding = True
                lean.command(ArmMode.JOINT_POSITION, jnt_pos_rad=lean.qpos,
                             jnt_trq_nm=self._zeros)
        lean.advance()

    def _advance_world(self, external: bool) -> None:
        """The world's cycle through ``SimWorld.advance`` (a world the lean path does not
        step: :func:`drivers.world.torque_step.unfit`)."""
        w = self.world
        if self.moving and not external:
            w.advance(ArmCommand(mode=ArmMode.JOINT_POSITION, jnt_pos_rad=self._q_d.copy(),
                                 jnt_trq_nm=np.zeros(7)))
            self._latched_external = False
        elif self.moving:
            if self._latched_external:  # the mode and zero gains stay latched in the world
                w.advance(ArmCommand(jnt_trq_nm=self._tau))
            else:
                w.advance(ArmCommand(mode=ArmMode.JOINT_IMPEDANCE,
                                     jnt_stiffness_nmprad=np.zeros(7),
                                     jnt_damping_ratio=np.zeros(7), jnt_trq_nm=self._tau))
                self._latched_external = True
        else:
            self._latched_external = False
            if not self._holding:
                self._holding = True
                w.advance(ArmCommand(mode=ArmMode.JOINT_POSITION, jnt_pos_rad=w.arm_qpos.copy(),
                                     jnt_trq_nm=np.zeros(7)))
            else:
                w.advance(None)
        # the world keeps its F/T sensor's samples for a reader: without one (the FR3's
        # wrench is the state's estimate) they are let go every cycle, not kept
        if not w.ft_read:
            w.ft_samples()

    def state(self) -> np.ndarray:
        """The current ``RobotState`` record (float32 arrays, as the robot sends it: a 0-d
        array of :data:`~drivers.franka.codec.ROBOT_STATE`, rewritten every cycle).

        Written in place through views of its fields (:class:`_StateViews`), each value
        cast to float32 as it is stored; the constant fields are written once, the others
        when what they report changed: the modes and error flags with the motion or the
        reflex, the commanded torques and joints when new ones came, the external
        wrench's fields while the tool touches (and once when it stops)."""
        if not self._decided:
            self._decide()
        v = self._views
        v.message_id[()] = self.message_id
        if self._lean is not None:
            if self._measured_at != self.steps:  # not written by the last step()
                self._measured_lean(v)
                self._measured_at = self.steps
            q = v.q
        else:
            q = self._measured_world(v)
        if self.moving:
            if self._q_d is not self._q_d_written:
                v.q_d[:] = self._q_d
                v.dq_d[:] = self._dq_d
                self._q_d_written = self._q_d
        else:
            v.q_d[:] = q
            if self._q_d_written is not None:
                v.dq_d[:] = 0.0
                self._q_d_written = None
        if self._tau is not self._tau_written:
            v.tau_j_d[:] = self._tau
            self._tau_written = self._tau
        modes = (self.moving, self._generator, self._controller, tuple(self.reflex))
        if modes != self._modes_of:
            self._write_modes(v)
            self._modes_of = modes
        if self._answered != self._answered_written:
            v.success_rate[()] = self._answered / WINDOW
            self._answered_written = self._answered
        return self._state

    def _write_modes(self, v: _StateViews) -> None:
        """The motion generator's, the controller's and the robot's modes, the error flags."""
        if self.moving:
            v.modes[:] = (self._generator, self._controller)
            v.robot_mode[()] = codec.RobotMode.MOVE
        else:
            v.modes[:] = (codec.MotionGeneratorMode.IDLE, codec.ControllerMode.JOINT_IMPEDANCE)
            v.robot_mode[()] = codec.RobotMode.REFLEX if self.reflex else codec.RobotMode.IDLE
        v.errors[:] = 0
        for name in self.reflex:
            v.errors[codec.ERROR_NAMES.index(name)] = 1
        v.reflex_reason[:] = v.errors

    def _measured_lean(self, v: _StateViews) -> None:
        """What the robot measures, from the lean path's end state (the pose and the
        joints written to both of their fields at once)."""
        lean = self._lean
        assert lean is not None
        v.poses_rot[...] = lean.tcp_xmat.reshape(3, 3)  # O_T_EE and O_T_EE_d, column-major
        v.poses_pos[...] = lean.tcp_xpos
        v.q_theta[...] = lean.qpos
        v.dq_dtheta[...] = lean.qvel
        lean.torques(v.tau_j)
        if lean.touching or self._wrench_written:
            v.tau_ext[:] = lean.tau_ext
            self._write_wrench(v, lean.contact, lean.tcp_xmat.reshape(3, 3))
            self._wrench_written = lean.touching

    def _measured_world(self, v: _StateViews) -> np.ndarray:
        """What the robot measures, from the world's state (``SimWorld.last_state``)."""
        w = self.world
        # held until the next one: the driver's truth of this state reads the same object
        # (SimWorld.last_state: the same object while someone holds it), computed once
        st = self._held_state = w.last_state
        pose = st.tcp_pose_m
        v.o_t_ee[...] = pose  # column-major, as libfranka's arrays
        v.o_t_ee_d[...] = pose
        q = st.jnt_pos_rad
        v.q[:] = q
        v.theta[:] = q
        dq = w.arm_qvel
        v.dq[:] = dq
        v.dtheta[:] = dq
        v.tau_j[:] = st.jnt_trq_nm
        v.tau_ext[:] = st.ext_jnt_trq_nm
        self._write_wrench(v, st.ext_wrench_n_nm, pose[:3, :3])
        return q

    def _write_wrench(self, v: _StateViews, wrench: F64, rot: F64) -> None:
        """The external wrench in the TCF (``K_F_ext_hat_K``) and in the base frame."""
        v.k_f_ext[:] = wrench
        o = self._wrench_o
        np.matmul(rot, wrench[:3], out=o[:3])
        np.matmul(rot, wrench[3:], out=o[3:])
        v.o_f_ext[:] = o

    def _fill_constants(self) -> None:
        s = self._state
        s["F_T_EE"] = self._f_t_ee.ravel(order="F")
        s["EE_T_K"] = np.eye(4).ravel(order="F")
        s["F_T_NE"] = s["F_T_EE"]
        s["NE_T_EE"] = s["EE_T_K"]
        s["O_ddP_O"] = _GRAVITY
        s["elbow"] = (0.0, -1.0)
        s["O_T_EE"][15] = s["O_T_EE_d"][15] = 1.0  # the poses' last row: 0 0 0 1


class _StateViews:
    """Views of the fields of a ``RobotState`` record that change from cycle to cycle
    (writing through them stores into the record; a name looked up once, not every
    cycle). The 4x4 poses are viewed column-major, as libfranka stores them."""

    def __init__(self, s: np.ndarray) -> None:
        self.message_id = s["message_id"]
        self.o_t_ee = s["O_T_EE"].reshape((4, 4), order="F")
        self.o_t_ee_d = s["O_T_EE_d"].reshape((4, 4), order="F")
        self.q, self.q_d, self.theta = s["q"], s["q_d"], s["theta"]
        self.dq, self.dq_d, self.dtheta = s["dq"], s["dq_d"], s["dtheta"]
        self.tau_j, self.tau_j_d = s["tau_J"], s["tau_J_d"]
        self.tau_ext = s["tau_ext_hat_filtered"]
        self.k_f_ext, self.o_f_ext = s["K_F_ext_hat_K"], s["O_F_ext_hat_K"]
        # motion_generator_mode and controller_mode are adjacent bytes
        fields = codec.ROBOT_STATE.fields
        assert fields is not None
        at = fields["motion_generator_mode"][1]
        self.modes = s.reshape(1).view(np.uint8)[at:at + 2]
        self.robot_mode = s["robot_mode"]
        self.errors, self.reflex_reason = s["errors"], s["reflex_reason"]
        self.success_rate = s["control_command_success_rate"]
        # fields written from one source at once: the rotations and the positions of
        # O_T_EE and O_T_EE_d (adjacent, column-major), q and theta, dq and dtheta
        raw = s.reshape(1).view(np.uint8)
        pose, f4 = fields["O_T_EE"][1], 4
        assert fields["O_T_EE_d"][1] == pose + 16 * f4
        self.poses_rot = np.ndarray((2, 3, 3), "<f4", raw, pose, (16 * f4, f4, 4 * f4))
        self.poses_pos = np.ndarray((2, 3), "<f4", raw, pose + 12 * f4, (16 * f4, f4))
        q, dq = fields["q"][1], fields["dq"][1]
        self.q_theta = np.ndarray((2, 7), "<f4", raw, q, (fields["theta"][1] - q, f4))
        self.dq_dtheta = np.ndarray((2, 7), "<f4", raw, dq, (fields["dtheta"][1] - dq, f4))
        for name, view in vars(self).items():  # views, never copies
            assert np.shares_memory(view, s), name

