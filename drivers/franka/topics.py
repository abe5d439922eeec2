"""Recording topics of the Franka back-end's extras, in :mod:`drivers.base.topics` classes.

``/robot/franka`` holds, per ffexp cycle, what only a Franka reports
(:class:`~drivers.franka.driver.FrankaExtras`: its robot mode, libfranka's
``control_command_success_rate``, the torques the driver's law commanded last, the
external joint torques and the count of reflex flags).
"""

from __future__ import annotations

from drivers.base.topics import CdrTopic, FieldSpec, MessageSpec

__all__ = ["CDR_TOPICS", "FRANKA_STATE"]

F = FieldSpec

FRANKA_STATE = MessageSpec(
    "ffexp_msgs/msg/FrankaState",
    (
        F("robot_mode", "int32", 1, "", "libfranka RobotMode (1 idle, 2 move, 4 reflex)"),
        F("success_rate", "float64", 1, "", "control_command_success_rate (last 100 cycles)"),
        F("missed_cycles", "uint32", 1, "", "1 kHz states the driver did not see (ids skipped)"),
        F("reflexes", "uint32", 1, "", "error flags set in this state"),
        F("tau_cmd_nm", "float64", 7, "N m", "the law's last joint torques (gravity excluded)"),
        F("tau_ext_nm", "float64", 7, "N m", "tau_ext_hat_filtered"),
    ),
    "What a Franka reports besides the neutral state, per ffexp cycle.",
)

CDR_TOPICS = (CdrTopic("/robot/franka", FRANKA_STATE, "every ffexp cycle, Franka back-ends"),)
