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

from collections import deque
from typing import Final

import numpy as np

from drivers.base.types import F64
from drivers.description import tool_tip_offset
from drivers.franka import codec
from drivers.sim.arm import ArmCommand, ArmMode
from drivers.sim.world import SimWorld

__all__ = ["WINDOW", "Fr3SimController", "flange_to_tcp"]

#: Cycles ``control_command_success_rate`` is taken over.
WINDOW: Final = 100
_GRAVITY: Final = (0.0, 0.0, -9.81)


def flange_to_tcp(world: SimWorld) -> F64:
    """The scene's tool from the flange to the TCP (the sensor, then the tool's tip; the
    TCF turned half a turn about z, as the world mounts it): libfranka's ``F_T_EE``."""
    t = np.eye(4)
    t[:3, :3] = np.diag([-1.0, -1.0, 1.0])
    t[2, 3] = world.scene.tool.sensor_height + tool_tip_offset(world.scene)
    return t


class Fr3SimController:
    """The FR3's controller on ``world`` (module docstring)."""

    def __init__(self, world: SimWorld) -> None:
        self.world = world
        desc = world.scene.arm.description
        self._lower = np.radians(desc.lower_limits_deg)
        self._upper = np.radians(desc.position_limits_deg)
        self._speed = np.radians(desc.velocity_limits_degps)
        self._tau_max = np.asarray(world.scene.arm.torque_limits, dtype=np.float64)
        self.message_id = 1
        self.moving = False
        """A motion with the external controller runs (libfranka's torque loop)."""
        self.ended: codec.MoveStatus | None = None
        """How the last motion ended, until it is reported (then ``None``)."""
        self.reflex: list[str] = []
        """The errors of the reflex in force (empty: none)."""
        self._answers: deque[bool] = deque([True] * WINDOW, maxlen=WINDOW)
        self._tau = np.zeros(desc.joints)
        self._generator = codec.MotionGeneratorMode.JOINT_VELOCITY
        self._controller = codec.ControllerMode.EXTERNAL_CONTROLLER
        self._q_d = world.arm_qpos.copy()
        self._dq_d = np.zeros(desc.joints)
        self._hold: ArmCommand | None = None
        self._f_t_ee = flange_to_tcp(world)
        self._state = np.zeros((), dtype=codec.ROBOT_STATE)
        self._fill_constants()
        self.steps = 0

    @property
    def success_rate(self) -> float:
        """The fraction of the last :data:`WINDOW` cycles answered."""
        return sum(self._answers) / WINDOW

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
        self._q_d = self.world.arm_qpos.copy()
        self._dq_d = np.zeros_like(self._q_d)
        self.moving, self.ended = True, None
        self._tau = np.zeros_like(self._tau)
        self._hold = None
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
        for the current state, or ``None``: none came), run the world, check the limits."""
        answered = command is not None and int(command["message_id"]) == self.message_id
        if self.moving:
            self._answers.append(answered)
        external = self._controller == codec.ControllerMode.EXTERNAL_CONTROLLER
        if answered and self.moving and not external:
            assert command is not None
            if self._generator == codec.MotionGeneratorMode.JOINT_POSITION:
                q_c = np.asarray(command["q_c"], dtype=np.float64)
                self._dq_d = (q_c - self._q_d) / self.world.cycle_s
                self._q_d = q_c
            else:
                self._dq_d = np.asarray(command["dq_c"], dtype=np.float64)
                self._q_d = self._q_d + self._dq_d * self.world.cycle_s
        if answered and self.moving and external:
            assert command is not None
            tau = np.asarray(command["tau_J_d"], dtype=np.float64)
            if not np.all(np.isfinite(tau)) or np.any(np.abs(tau) > self._tau_max):
                self._reflex(["tau_j_range_violation"])
            else:
                self._tau = tau
        if answered and self.moving:
            assert command is not None
            if command["motion_generation_finished"] or command["torque_command_finished"]:
                self.finish_motion()
        w = self.world
        if self.moving and not external:
            w.advance(ArmCommand(mode=ArmMode.JOINT_POSITION, jnt_pos_rad=self._q_d.copy(),
                                 jnt_trq_nm=np.zeros(7)))
        elif self.moving:
            w.advance(ArmCommand(mode=ArmMode.JOINT_IMPEDANCE, jnt_stiffness_nmprad=np.zeros(7),
                                 jnt_damping_ratio=np.zeros(7), jnt_trq_nm=self._tau))
        else:
            if self._hold is None:
                self._hold = ArmCommand(mode=ArmMode.JOINT_POSITION,
                                        jnt_pos_rad=w.arm_qpos.copy(), jnt_trq_nm=np.zeros(7))
                w.advance(self._hold)
            else:
                w.advance(None)
        self.steps += 1
        self.message_id += 1
        if self.moving:
            q, dq = w.arm_qpos, w.arm_qvel
            names = []
            if np.any(q <= self._lower) or np.any(q >= self._upper):
                names.append("joint_position_limits_violation")
            if np.any(np.abs(dq) > self._speed):
                names.append("joint_velocity_violation")
            if names:
                self._reflex(names)

    def state(self) -> np.ndarray:
        """The current ``RobotState`` record (float32 arrays, as the robot sends it: a 0-d
        array of :data:`~drivers.franka.codec.ROBOT_STATE`, rewritten every cycle)."""
        s = self._state
        w = self.world
        st = w.last_state
        s["message_id"] = self.message_id
        pose = st.tcp_pose_m
        s["O_T_EE"] = pose.ravel(order="F")
        s["O_T_EE_d"] = s["O_T_EE"]
        s["q"] = st.jnt_pos_rad
        s["q_d"] = self._q_d if self.moving else st.jnt_pos_rad
        s["dq_d"] = self._dq_d if self.moving else 0.0
        s["dq"] = w.arm_qvel
        s["tau_J_d"] = self._tau
        s["tau_J"] = st.jnt_trq_nm
        s["tau_ext_hat_filtered"] = st.ext_jnt_trq_nm
        wrench = st.ext_wrench_n_nm
        rot = pose[:3, :3]
        s["K_F_ext_hat_K"] = wrench
        s["O_F_ext_hat_K"] = np.concatenate((rot @ wrench[:3], rot @ wrench[3:]))
        s["theta"] = st.jnt_pos_rad
        s["dtheta"] = s["dq"]
        if self.moving:
            s["motion_generator_mode"] = self._generator
            s["controller_mode"] = self._controller
            s["robot_mode"] = codec.RobotMode.MOVE
        else:
            s["motion_generator_mode"] = codec.MotionGeneratorMode.IDLE
            s["controller_mode"] = codec.ControllerMode.JOINT_IMPEDANCE
            s["robot_mode"] = codec.RobotMode.REFLEX if self.reflex else codec.RobotMode.IDLE
        flags = np.zeros(len(codec.ERROR_NAMES), dtype=np.uint8)
        for name in self.reflex:
            flags[codec.ERROR_NAMES.index(name)] = 1
        s["errors"] = flags
        s["reflex_reason"] = flags
        s["control_command_success_rate"] = self.success_rate
        return s

    def _fill_constants(self) -> None:
        s = self._state
        s["F_T_EE"] = self._f_t_ee.ravel(order="F")
        s["EE_T_K"] = np.eye(4).ravel(order="F")
        s["F_T_NE"] = s["F_T_EE"]
        s["NE_T_EE"] = s["EE_T_K"]
        s["O_ddP_O"] = _GRAVITY
        s["elbow"] = (0.0, -1.0)
