"""The RTDE variables ffexp knows, with their field types (RTDE Guide, e-Series).

A subset of the guide's tables: the robot, joint, TCP, safety and status
outputs a force-control experiment reads, and the general-purpose registers
both ways. Names are the controller's, case and all (``actual_TCP_pose``).
Registers: ``input_/output_int_register_N`` and ``..._double_register_N`` for
N in 0..47 (24..47 are the "upper range" that external clients such as
fieldbus adapters leave free), ``input_/output_bit_register_N`` for N in
64..127 (0..63 are the packed ``..._bit_registers0_to_31`` /
``32_to_63`` words). Every input variable can also be read back as an output.
"""

from __future__ import annotations

from typing import Final

#: Output variables (controller -> client), name -> field type.
OUTPUTS: Final[dict[str, str]] = {
    "timestamp": "DOUBLE",  # time since the controller started [s]
    "target_q": "VECTOR6D",
    "target_qd": "VECTOR6D",
    "target_qdd": "VECTOR6D",
    "target_current": "VECTOR6D",
    "target_moment": "VECTOR6D",
    "actual_q": "VECTOR6D",  # joint positions [rad]
    "actual_qd": "VECTOR6D",  # joint velocities [rad/s]
    "actual_current": "VECTOR6D",
    "joint_control_output": "VECTOR6D",
    "actual_TCP_pose": "VECTOR6D",  # x, y, z [m], rotation vector [rad], base frame
    "actual_TCP_speed": "VECTOR6D",  # [m/s, rad/s], base frame
    "actual_TCP_force": "VECTOR6D",  # generalised TCP wrench [N, N m], base frame
    "target_TCP_pose": "VECTOR6D",
    "target_TCP_speed": "VECTOR6D",
    "actual_digital_input_bits": "UINT64",
    "joint_temperatures": "VECTOR6D",
    "actual_execution_time": "DOUBLE",
    "robot_mode": "INT32",
    "joint_mode": "VECTOR6INT32",
    "safety_mode": "INT32",
    "safety_status": "INT32",
    "actual_tool_accelerometer": "VECTOR3D",
    "speed_scaling": "DOUBLE",
    "target_speed_fraction": "DOUBLE",
    "actual_momentum": "DOUBLE",
    "actual_main_voltage": "DOUBLE",
    "actual_robot_voltage": "DOUBLE",
    "actual_robot_current": "DOUBLE",
    "actual_joint_voltage": "VECTOR6D",
    "actual_digital_output_bits": "UINT64",
    "runtime_state": "UINT32",
    "elbow_position": "VECTOR3D",
    "elbow_velocity": "VECTOR3D",
    "robot_status_bits": "UINT32",
    "safety_status_bits": "UINT32",
    "analog_io_types": "UINT32",
    "standard_analog_input0": "DOUBLE",
    "standard_analog_input1": "DOUBLE",
    "standard_analog_output0": "DOUBLE",
    "standard_analog_output1": "DOUBLE",
    "io_current": "DOUBLE",
    "tool_mode": "UINT32",
    "tool_analog_input_types": "UINT32",
    "tool_analog_input0": "DOUBLE",
    "tool_analog_input1": "DOUBLE",
    "tool_output_voltage": "INT32",
    "tool_output_current": "DOUBLE",
    "tool_temperature": "DOUBLE",
    "tcp_force_scalar": "DOUBLE",
    "output_bit_registers0_to_31": "UINT32",
    "output_bit_registers32_to_63": "UINT32",
    "tool_output_mode": "UINT8",
    "tool_digital_output0_mode": "UINT8",
    "tool_digital_output1_mode": "UINT8",
    "payload": "DOUBLE",
    "payload_cog": "VECTOR3D",
    "payload_inertia": "VECTOR6D",
    "script_control_line": "UINT32",
    "ft_raw_wrench": "VECTOR6D",  # the tool flange sensor's raw wrench [N, N m]
    "joint_position_deviation_ratio": "DOUBLE",
    "collision_detection_ratio": "DOUBLE",
}

#: Input variables (client -> controller), name -> field type.
INPUTS: Final[dict[str, str]] = {
    "speed_slider_mask": "UINT32",
    "speed_slider_fraction": "DOUBLE",
    "standard_digital_output_mask": "UINT8",
    "standard_digital_output": "UINT8",
    "configurable_digital_output_mask": "UINT8",
    "configurable_digital_output": "UINT8",
    "tool_digital_output_mask": "UINT8",
    "tool_digital_output": "UINT8",
    "standard_analog_output_mask": "UINT8",
    "standard_analog_output_type": "UINT8",
    "standard_analog_output_0": "DOUBLE",
    "standard_analog_output_1": "DOUBLE",
    "input_bit_registers0_to_31": "UINT32",
    "input_bit_registers32_to_63": "UINT32",
}

#: Register numbers of the int and double registers, and of the single bit registers.
WORD_REGISTERS: Final = range(48)
BIT_REGISTERS: Final = range(64, 128)

for _n in WORD_REGISTERS:
    INPUTS[f"input_int_register_{_n}"] = "INT32"
    INPUTS[f"input_double_register_{_n}"] = "DOUBLE"
    OUTPUTS[f"output_int_register_{_n}"] = "INT32"
    OUTPUTS[f"output_double_register_{_n}"] = "DOUBLE"
for _n in BIT_REGISTERS:
    INPUTS[f"input_bit_register_{_n}"] = "BOOL"
    OUTPUTS[f"output_bit_register_{_n}"] = "BOOL"
del _n

# Every input can be read back as an output (the guide lists the input registers among them).
OUTPUTS.update({name: t for name, t in INPUTS.items() if name not in OUTPUTS})

#: ``robot_mode`` values (RTDE Guide).
ROBOT_MODE: Final[dict[int, str]] = {
    -1: "NO_CONTROLLER", 0: "DISCONNECTED", 1: "CONFIRM_SAFETY", 2: "BOOTING",
    3: "POWER_OFF", 4: "POWER_ON", 5: "IDLE", 6: "BACKDRIVE", 7: "RUNNING",
    8: "UPDATING_FIRMWARE",
}
#: ``safety_mode`` values (RTDE Guide).
SAFETY_MODE: Final[dict[int, str]] = {
    1: "NORMAL", 2: "REDUCED", 3: "PROTECTIVE_STOP", 4: "RECOVERY",
    5: "SAFEGUARD_STOP", 6: "SYSTEM_EMERGENCY_STOP", 7: "ROBOT_EMERGENCY_STOP",
    8: "VIOLATION", 9: "FAULT", 10: "VALIDATE_JOINT_ID", 11: "UNDEFINED_SAFETY_MODE",
    12: "AUTOMATIC_MODE_SAFEGUARD_STOP", 13: "SYSTEM_THREE_POSITION_ENABLING_STOP",
}
#: ``safety_status_bits`` bit numbers (RTDE Guide).
SAFETY_STATUS_BIT: Final[dict[str, int]] = {
    "normal_mode": 0, "reduced_mode": 1, "protective_stopped": 2, "recovery_mode": 3,
    "safeguard_stopped": 4, "system_emergency_stopped": 5, "robot_emergency_stopped": 6,
    "emergency_stopped": 7, "violation": 8, "fault": 9, "stopped_due_to_safety": 10,
}
#: ``runtime_state`` values (RTDE Guide).
RUNTIME_STATE: Final[dict[int, str]] = {
    0: "STOPPING", 1: "STOPPED", 2: "PLAYING", 3: "PAUSING", 4: "PAUSED", 5: "RESUMING",
}


def output_type(name: str) -> str | None:
    """The field type of output variable ``name``, or ``None`` if it is not known."""
    return OUTPUTS.get(name)


def input_type(name: str) -> str | None:
    """The field type of input variable ``name``, or ``None`` if it is not known."""
    return INPUTS.get(name)
