"""Recording topics of the UR back-end's extras, in :mod:`drivers.base.topics` classes.

``/robot/ur`` holds, per controller cycle, what only a UR reports
(:class:`~drivers.ur.driver.UrExtras`: its modes and safety bits, the state of
ffexp's URScript program and the command it applied, the joint speeds and the
flange sensor's raw wrench); the fields are same-named attributes of the extras.
:data:`drivers.ur.backend.BACKEND` contributes the topic to :mod:`drivers.registry`.
"""

from __future__ import annotations

from drivers.base.topics import CdrTopic, FieldSpec, MessageSpec

__all__ = ["CDR_TOPICS", "UR_STATE"]

F = FieldSpec

UR_STATE = MessageSpec(
    "ffexp_msgs/msg/UrState",
    (
        F("robot_mode", "int32", 1, "", "RTDE robot_mode (7 RUNNING)"),
        F("safety_mode", "int32", 1, "", "RTDE safety_mode (1 NORMAL, 3 PROTECTIVE_STOP)"),
        F("safety_status_bits", "uint32", 1, "", "RTDE safety_status_bits"),
        F("runtime_state", "int32", 1, "", "RTDE runtime_state (2 PLAYING)"),
        F("script_state", "int32", 1, "", "ffexp_control: 1 running, 2 ended, 3 held (stale)"),
        F("applied_seq", "int32", 1, "", "sequence number of the command the program applied"),
        F("skipped_packages", "uint32", 1, "", "data packages skipped so far (reader behind)"),
        F("joint_vel_radps", "float64", 6, "rad/s", "actual_qd"),
        F("ft_raw_wrench", "float64", 6, "N, N m", "the flange sensor's raw wrench (UR's frame)"),
    ),
    "What a UR reports besides the neutral state, per controller cycle.",
)

CDR_TOPICS = (CdrTopic("/robot/ur", UR_STATE, "every controller cycle, UR back-ends"),)
