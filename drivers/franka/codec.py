"""libfranka's network protocol (the FCI research interface, server version 10): the wire
layouts as numpy structured dtypes, packed and little-endian. Pure: no sockets.

Written from the layout libfranka-common publishes (Apache-2.0,
``research_interface/robot/service_types.h`` and ``rbk_types.h``), no code copied:

* TCP, the command port (1337): every message is a :data:`HEADER` (``command``,
  ``command_id``, ``size``: the whole message's bytes) and the command's payload.
  ``Connect`` carries the client's protocol version and the UDP port it listens on;
  the answer a status (0 success, 1 incompatible library version) and the server's
  version. ``Move`` starts a motion (controller mode, motion generator mode, two
  deviations of three doubles); its answers are a status byte, first ``kMotionStarted``,
  then how it ended.
* UDP: the robot sends a :data:`ROBOT_STATE` to the client's port every millisecond
  (arrays of float32 since the protocol's "reduce RobotState size"; libfranka 0.21
  expects two accelerometer arrays of 18 after ``dtheta``: 1377 bytes, measured against
  pylibfranka 0.21.3 and matching the franky-sim server's layout); the client answers
  each with a :data:`ROBOT_COMMAND` carrying the state's ``message_id`` (doubles).

The byte offsets are the layout's: ``tests/test_franka_codec.py`` checks them.
"""

from __future__ import annotations

import struct
from enum import IntEnum
from typing import Final

import numpy as np

__all__ = [
    "COMMAND_PORT", "COMMAND_TORQUES", "CONNECT_REQUEST", "CONNECT_RESPONSE", "ERROR_NAMES",
    "HEADER", "MOVE_REQUEST", "MOVE_RESPONSE", "ROBOT_COMMAND", "ROBOT_STATE", "STATUS_RESPONSE",
    "VERSION", "Command", "ConnectStatus", "ControllerMode", "MotionGeneratorMode",
    "MoveControllerMode", "MoveMotionGeneratorMode", "MoveStatus", "RobotMode",
    "decode", "error_names", "header_of", "message",
]

#: The protocol version this codec speaks (libfranka >= 0.18, robot system >= 5.9).
VERSION: Final = 10
#: The robot's TCP command port.
COMMAND_PORT: Final = 1337


class Command(IntEnum):
    """``CommandHeader.command`` (libfranka 0.21: ``kLoadModelLibrary`` is gone and
    ``kGetRobotModel`` is 11, as pylibfranka 0.21.3 sends it)."""

    CONNECT = 0
    MOVE = 1
    STOP_MOVE = 2
    SET_COLLISION_BEHAVIOR = 3
    SET_JOINT_IMPEDANCE = 4
    SET_CARTESIAN_IMPEDANCE = 5
    SET_GUIDING_MODE = 6
    SET_EE_TO_K = 7
    SET_NE_TO_EE = 8
    SET_LOAD = 9
    AUTOMATIC_ERROR_RECOVERY = 10
    GET_ROBOT_MODEL = 11


class ConnectStatus(IntEnum):
    SUCCESS = 0
    INCOMPATIBLE_LIBRARY_VERSION = 1


class MoveStatus(IntEnum):
    SUCCESS = 0
    MOTION_STARTED = 1
    PREEMPTED = 2
    PREEMPTED_DUE_TO_ACTIVATED_SAFETY_FUNCTIONS = 3
    COMMAND_REJECTED_DUE_TO_ACTIVATED_SAFETY_FUNCTIONS = 4
    COMMAND_NOT_POSSIBLE_REJECTED = 5
    START_AT_SINGULAR_POSE_REJECTED = 6
    INVALID_ARGUMENT_REJECTED = 7
    REFLEX_ABORTED = 8
    EMERGENCY_ABORTED = 9
    INPUT_ERROR_ABORTED = 10
    ABORTED = 11


class MoveControllerMode(IntEnum):
    """``Move::Request.controller_mode`` (uint32)."""

    JOINT_IMPEDANCE = 0
    CARTESIAN_IMPEDANCE = 1
    EXTERNAL_CONTROLLER = 2


class MoveMotionGeneratorMode(IntEnum):
    """``Move::Request.motion_generator_mode`` (uint32)."""

    JOINT_POSITION = 0
    JOINT_VELOCITY = 1
    CARTESIAN_POSITION = 2
    CARTESIAN_VELOCITY = 3
    NONE = 4


class MotionGeneratorMode(IntEnum):
    """``RobotState.motion_generator_mode`` (uint8)."""

    IDLE = 0
    JOINT_POSITION = 1
    JOINT_VELOCITY = 2
    CARTESIAN_POSITION = 3
    CARTESIAN_VELOCITY = 4
    NONE = 5


class ControllerMode(IntEnum):
    """``RobotState.controller_mode`` (uint8)."""

    JOINT_IMPEDANCE = 0
    CARTESIAN_IMPEDANCE = 1
    EXTERNAL_CONTROLLER = 2
    OTHER = 3


class RobotMode(IntEnum):
    """``RobotState.robot_mode`` (uint8)."""

    OTHER = 0
    IDLE = 1
    MOVE = 2
    GUIDING = 3
    REFLEX = 4
    USER_STOPPED = 5
    AUTOMATIC_ERROR_RECOVERY = 6


#: The robot's error and reflex-reason flags, in the order of ``errors`` and
#: ``reflex_reason`` (libfranka's ``franka::Errors`` names them alike).
ERROR_NAMES: Final = (
    "joint_position_limits_violation", "cartesian_position_limits_violation",
    "self_collision_avoidance_violation", "joint_velocity_violation",
    "cartesian_velocity_violation", "force_control_safety_violation", "joint_reflex",
    "cartesian_reflex", "max_goal_pose_deviation_violation",
    "max_path_pose_deviation_violation", "cartesian_velocity_profile_safety_violation",
    "joint_position_motion_generator_start_pose_invalid",
    "joint_motion_generator_position_limits_violation",
    "joint_motion_generator_velocity_limits_violation",
    "joint_motion_generator_velocity_discontinuity",
    "joint_motion_generator_acceleration_discontinuity",
    "cartesian_position_motion_generator_start_pose_invalid",
    "cartesian_motion_generator_elbow_limit_violation",
    "cartesian_motion_generator_velocity_limits_violation",
    "cartesian_motion_generator_velocity_discontinuity",
    "cartesian_motion_generator_acceleration_discontinuity",
    "cartesian_motion_generator_elbow_sign_inconsistent",
    "cartesian_motion_generator_start_elbow_invalid",
    "cartesian_motion_generator_joint_position_limits_violation",
    "cartesian_motion_generator_joint_velocity_limits_violation",
    "cartesian_motion_generator_joint_velocity_discontinuity",
    "cartesian_motion_generator_joint_acceleration_discontinuity",
    "cartesian_position_motion_generator_invalid_frame",
    "force_controller_desired_force_tolerance_violation", "controller_torque_discontinuity",
    "start_elbow_sign_inconsistent", "communication_constraints_violation",
    "power_limit_violation", "joint_p2p_insufficient_torque_for_planning",
    "tau_j_range_violation", "instability_detected", "joint_move_in_wrong_direction",
    "cartesian_spline_motion_generator_violation",
    "joint_via_motion_generator_planning_joint_limit_violation",
    "base_acceleration_initialization_timeout", "base_acceleration_invalid_reading",
)

_F4, _F8, _U8 = "<f4", "<f8", "u1"

#: ``CommandHeader`` (12 bytes).
HEADER: Final = np.dtype([("command", "<u4"), ("command_id", "<u4"), ("size", "<u4")])

#: ``RobotState`` as the robot sends it over UDP (packed; arrays float32).
ROBOT_STATE: Final = np.dtype([
    ("message_id", "<u8"),
    ("O_T_EE", _F4, 16), ("O_T_EE_d", _F4, 16), ("F_T_EE", _F4, 16), ("EE_T_K", _F4, 16),
    ("F_T_NE", _F4, 16), ("NE_T_EE", _F4, 16),
    ("m_ee", _F4), ("I_ee", _F4, 9), ("F_x_Cee", _F4, 3),
    ("m_load", _F4), ("I_load", _F4, 9), ("F_x_Cload", _F4, 3),
    ("elbow", _F4, 2), ("elbow_d", _F4, 2),
    ("tau_J", _F4, 7), ("tau_J_d", _F4, 7), ("dtau_J", _F4, 7),
    ("q", _F4, 7), ("q_d", _F4, 7), ("dq", _F4, 7), ("dq_d", _F4, 7), ("ddq_d", _F4, 7),
    ("joint_contact", _F4, 7), ("cartesian_contact", _F4, 6),
    ("joint_collision", _F4, 7), ("cartesian_collision", _F4, 6),
    ("tau_ext_hat_filtered", _F4, 7), ("O_F_ext_hat_K", _F4, 6), ("K_F_ext_hat_K", _F4, 6),
    ("O_dP_EE_d", _F4, 6), ("O_ddP_O", _F4, 3),
    ("elbow_c", _F4, 2), ("delbow_c", _F4, 2), ("ddelbow_c", _F4, 2),
    ("O_T_EE_c", _F4, 16), ("O_dP_EE_c", _F4, 6), ("O_ddP_EE_c", _F4, 6),
    ("theta", _F4, 7), ("dtheta", _F4, 7),
    ("accelerometer_top", _F4, 18), ("accelerometer_bottom", _F4, 18),
    ("motion_generator_mode", _U8), ("controller_mode", _U8),
    ("errors", _U8, 41), ("reflex_reason", _U8, 41),
    ("robot_mode", _U8), ("control_command_success_rate", _F4),
])

#: ``RobotCommand`` as the client sends it over UDP (packed; doubles).
ROBOT_COMMAND: Final = np.dtype([
    ("message_id", "<u8"),
    ("q_c", _F8, 7), ("dq_c", _F8, 7), ("O_T_EE_c", _F8, 16), ("O_dP_EE_c", _F8, 6),
    ("elbow_c", _F8, 2), ("valid_elbow", _U8), ("motion_generation_finished", _U8),
    ("tau_J_d", _F8, 7), ("torque_command_finished", _U8),
])

#: What a torque loop's cycle reads of a ``RobotCommand``, in one unpacking: ``message_id``,
#: ``motion_generation_finished``, the seven ``tau_J_d``, ``torque_command_finished``.
COMMAND_TORQUES: Final = struct.Struct("<Q305xB7dB")

CONNECT_REQUEST: Final = np.dtype([("header", HEADER), ("version", "<u2"), ("udp_port", "<u2")])
CONNECT_RESPONSE: Final = np.dtype([("header", HEADER), ("status", _U8), ("version", "<u2")])
_DEVIATION = np.dtype([("translation", _F8), ("rotation", _F8), ("elbow", _F8)])
MOVE_REQUEST: Final = np.dtype([
    ("header", HEADER), ("controller_mode", "<u4"), ("motion_generator_mode", "<u4"),
    ("maximum_path_deviation", _DEVIATION), ("maximum_goal_pose_deviation", _DEVIATION),
])
MOVE_RESPONSE: Final = np.dtype([("header", HEADER), ("status", _U8)])
#: The answer of every other command: its status (0: success).
STATUS_RESPONSE: Final = MOVE_RESPONSE


def message(dtype: np.dtype, command: Command, command_id: int, **fields: object) -> bytes:
    """One TCP message of ``dtype`` (its header filled: ``size`` the message's bytes)."""
    rec = np.zeros((), dtype=dtype)
    rec["header"]["command"] = int(command)
    rec["header"]["command_id"] = command_id
    rec["header"]["size"] = dtype.itemsize
    for name, value in fields.items():
        rec[name] = value
    return rec.tobytes()


def header_of(data: bytes) -> np.void:
    """The header of a TCP message (its first 12 bytes)."""
    rec: np.void = np.frombuffer(data[:HEADER.itemsize], dtype=HEADER)[0]
    return rec


def decode(dtype: np.dtype, data: bytes | bytearray | memoryview) -> np.void:
    """One record of ``dtype`` from exactly its bytes (ValueError otherwise)."""
    if len(data) != dtype.itemsize:
        raise ValueError(f"{len(data)} bytes, a {dtype.names and dtype.names[0]}… record is "
                         f"{dtype.itemsize}")
    rec: np.void = np.frombuffer(bytes(data), dtype=dtype)[0]
    return rec


def error_names(flags: np.ndarray) -> list[str]:
    """The names of the flags set in an ``errors`` or ``reflex_reason`` array."""
    return [ERROR_NAMES[i] for i in np.flatnonzero(np.asarray(flags))]
