"""Topics of the FRI link's own truth: a group of :mod:`ffexp.recording.topics`.

Message specs and topics are defined here with the classes of
:mod:`ffexp.recording.schema`; ``topics.py`` puts them in the one registry
(``CDR_TOPICS``, ``JSON_TOPICS``), so every recorder, reader and ``ffexp topics``
sees them.

``/robot/link_driver`` holds the UDP remote driver's own counters at each cycle
(cumulative since the link was opened), beside the KRC's view on ``/robot/link``:
what arrived, from whom, what was missing, late, doubled or out of order, and
how the cycle was answered. The fields are same-named attributes of
:class:`drivers.fri.types.RemoteMeasurement`.
"""

from __future__ import annotations

from ffexp.recording.schema import CdrTopic, FieldSpec, JsonTopic, MessageSpec

F = FieldSpec

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

CDR: tuple[CdrTopic, ...] = (
    CdrTopic("/robot/link_driver", LINK_DRIVER, "every controller cycle, FRI over UDP"),
)
JSON: tuple[JsonTopic, ...] = ()
