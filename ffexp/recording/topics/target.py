"""Topics of the target tracker and the alignment verdict: a group of :mod:`ffexp.recording.topics`.

Message specs and topics are defined here with the classes of
:mod:`ffexp.recording.schema`; ``topics.py`` puts them in the one registry
(``CDR_TOPICS``, ``JSON_TOPICS``), so every recorder, reader and ``ffexp topics``
sees them.

``/target/pose`` holds every new observation of the rig's target tracker (a
camera or the simulator's camera model), written at the cycle it was first
seen; the same pose goes to ``/tf`` as the frame ``target_tracked`` in
``base``. ``/alignment/verdict`` says who judges the alignment (ground truth,
the tracker or the observer), when that changes and, at the end, the run's
verdict with its evidence and, in simulation, the truth's verdict beside it.
"""

from __future__ import annotations

from ffexp.recording.schema import CdrTopic, FieldSpec, JsonTopic, MessageSpec

F = FieldSpec

TARGET_POSE = MessageSpec(
    "ffexp_msgs/msg/TargetPose",
    (
        F("time_ns", "int64", 1, "ns", "when the pose was true (exposure), robot clock"),
        F("pose", "float64", 16, "m", "target block frame in the base frame, 4x4 row-major"),
        F("mouth", "float64", 16, "m", "target funnel mouth frame in the base frame, 4x4"),
        F("valid", "uint8", 1, "", "1: a pose; 0: marker or stream lost (pose: the last one)"),
        F("frames", "uint32", 1, "", "observations since the tracker started"),
        F("age_s", "float64", 1, "s", "robot time now minus time_ns"),
    ),
    "The target as the rig's tracker saw it.",
)

#: Frame name of the tracked target on ``/tf`` (the simulator's own is ``target``).
TRACKED_FRAME = "target_tracked"

VERDICT_SCHEMA = {
    "title": "ffexp.Verdict",
    "type": "object",
    "properties": {
        "label": {"type": "string", "enum": ["aligned", "not aligned", "unverified"]},
        "source": {"type": "string", "enum": ["truth", "tracker", "observer", "settings"],
                   "description": "who judged"},
        "reason": {"type": "string"},
        "truth": {"type": "string", "description": "the simulator's verdict ('' on hardware)"},
        "final": {"type": "boolean", "description": "the run's verdict (else: a source change)"},
        "evidence": {"type": "object", "additionalProperties": {"type": "number"},
                     "description": "numbers the verdict rests on (SI units in the names)"},
    },
}

CDR: tuple[CdrTopic, ...] = (
    CdrTopic("/target/pose", TARGET_POSE, "every new tracker observation (tracker rigs)"),
)
JSON: tuple[JsonTopic, ...] = (
    JsonTopic("/alignment/verdict", "ffexp.Verdict", VERDICT_SCHEMA, "on source change and at end",
              "Who judges the alignment, and the run's verdict with its evidence."),
)
