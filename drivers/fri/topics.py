"""Recording topics of the FRI back-end's extras, in :mod:`drivers.base.topics` classes.

``/robot/measurement`` holds each FRI measurement packet
(:class:`~drivers.fri.types.FriMeasurement`), ``/robot/link`` the KRC's view of
the link, ``/robot/command`` the command packet sent in answer
(:class:`~drivers.fri.types.FriCommand`); the fields are same-named attributes
of those extras (their ``topics()`` names these topics).

``/robot/link_driver`` holds the UDP remote driver's own counters at each cycle
(cumulative since the link was opened), beside the KRC's view on ``/robot/link``:
what arrived, from whom, what was missing, late, doubled or out of order, and
how the cycle was answered. The fields are same-named attributes of
:class:`drivers.fri.types.RemoteMeasurement`.

:data:`drivers.fri.backend.BACKEND` contributes them to :mod:`drivers.registry`,
from which the recording's registry (:mod:`ffexp.recording.topics`) takes them.
"""

from __future__ import annotations

from drivers.base.topics import CdrTopic, FieldSpec, MessageSpec

__all__ = ["CDR_TOPICS", "COMMAND", "LINK", "LINK_DRIVER", "MEASUREMENT"]

F = FieldSpec

MEASUREMENT = MessageSpec(
    "ffexp_msgs/msg/Measurement",
    (
        F("msr_jnt_pos", "float64", 7, "rad", "measured joint positions"),
        F("cmd_jnt_pos", "float64", 7, "rad", "commanded joint positions"),
        F("cmd_jnt_pos_fri_offset", "float64", 7, "rad"),
        F("msr_cart_pos", "float64", 16, "m", "measured TCP pose, 4x4 row-major"),
        F("cmd_cart_pos", "float64", 16, "m", "commanded TCP pose, 4x4 row-major"),
        F("msr_jnt_trq", "float64", 7, "N m"),
        F("est_ext_jnt_trq", "float64", 7, "N m", "external joint torques (KRC estimate)"),
        F("est_ext_tcp_ft", "float64", 6, "N, N m", "external TCP wrench (KRC estimate), TCF"),
        F("jacobian", "float64", 42, "", "6x7 row-major, rows vx vy vz wx wy wz (TCF)"),
        F("mass_matrix", "float64", 49, "kg m^2", "7x7 joint-space inertia"),
        F("gravity", "float64", 7, "N m", "gravity joint torques"),
        F("temperature", "float64", 7, "degC"),
        F("seq", "uint32", 1, "", "KRC send sequence counter"),
        F("state", "int32", 1, "", "FRI state: -1 invalid, 0 off, 1 mon, 2 cmd"),
        F("quality", "int32", 1, "", "FRI quality: 0 unacceptable, 1 bad, 2 ok, 3 perfect"),
        F("control", "int32", 1, "", "control mode: 1 joint pos, 2 cart imp, 3 joint imp"),
        F("power", "uint32"),
        F("error", "uint32"),
        F("warning", "uint32"),
    ),
    "One FRI measurement packet per controller cycle.",
)

LINK = MessageSpec(
    "ffexp_msgs/msg/LinkStats",
    (
        F("answer_rate", "float64", 1, "", "fraction of cycles answered (last 100)"),
        F("latency_s", "float64", 1, "s"),
        F("jitter_s", "float64", 1, "s"),
        F("miss_rate", "float64", 1, ""),
        F("miss_counter", "uint32"),
        F("state", "int32"),
        F("quality", "int32"),
    ),
    "FRI link statistics per cycle.",
)

COMMAND = MessageSpec(
    "ffexp_msgs/msg/Command",
    (
        F("jnt_pos", "float64", 7, "rad"),
        F("cart_pos", "float64", 16, "m", "4x4 row-major"),
        F("add_jnt_trq", "float64", 7, "N m"),
        F("add_tcp_ft", "float64", 6, "N, N m", "superposed wrench, TCF"),
        F("jnt_stiffness", "float64", 7, "N m/rad"),
        F("jnt_damping", "float64", 7, "", "normalised"),
        F("cart_stiffness", "float64", 6, "N/m, N m/rad", "x y z rx ry rz"),
        F("cart_damping", "float64", 6, "", "normalised, x y z rx ry rz"),
        F("flags", "uint32", 1, "", "FRI cmdFlags"),
        F("control", "int32", 1, "", "requested control mode"),
    ),
    "The FRI command packet sent in answer to each measurement (what the KRC takes).",
)

LINK_DRIVER = MessageSpec(
    "ffexp_msgs/msg/LinkDriver",
    (
        F("received", "uint32", 1, "", "datagrams received on the port, any source"),
        F("foreign", "uint32", 1, "", "datagrams from another address than the robot's"),
        F("foreign_ipv4", "uint32", 1, "", "the last foreign sender's IPv4 address (0: none)"),
        F("foreign_port", "uint32", 1, "", "the last foreign sender's UDP port (0: none)"),
        F("rejected", "uint32", 1, "", "datagrams from the robot the codec rejected"),
        F("accepted", "uint32", 1, "", "measurements accepted"),
        F("lost", "uint32", 1, "", "measurements missing in the sequence, never received"),
        F("duplicates", "uint32", 1, "", "measurements received twice (re-answered)"),
        F("reordered", "uint32", 1, "", "measurements that came after a newer one"),
        F("restarts", "uint32", 1, "", "sequence jumps back taken as a KRC restart"),
        F("implausible", "uint32", 1, "", "measurements with impossible contents"),
        F("answers", "uint32", 1, "", "command datagrams sent"),
        F("runner_answers", "uint32", 1, "", "cycles answered with that cycle's command"),
        F("deadline_answers", "uint32", 1, "",
          "cycles answered at the deadline with the previous command"),
        F("runner_late", "uint32", 1, "", "commands that came after their cycle was answered"),
        F("skipped", "uint32", 1, "", "measurements the runner never saw"),
        F("turnaround_s", "float64", 1, "s", "packet received -> answer sent, last cycle"),
    ),
    "The FRI remote driver's own link counters per cycle (cumulative).",
)

CDR_TOPICS: tuple[CdrTopic, ...] = (
    CdrTopic("/robot/measurement", MEASUREMENT, "every controller cycle, FRI back-ends"),
    CdrTopic("/robot/link", LINK, "every controller cycle, FRI back-ends"),
    CdrTopic("/robot/command", COMMAND, "every controller cycle, FRI back-ends"),
    CdrTopic("/robot/link_driver", LINK_DRIVER, "every controller cycle, FRI over UDP"),
)
