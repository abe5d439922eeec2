"""The simulator's recording topics: its ground truth (:class:`~drivers.base.types.GroundTruth`).

Neutral: the truth's own fields on ``/sim/truth``, every free-moving body of the
scene on ``/sim/body/<name>`` and every named frame on ``/sim/site/<name>`` (a topic
name ending in ``/*`` stands for every topic of that prefix with one more name).
A frame fixed on a free body (the funnel's mouth on the target) is not written
every cycle: ``/sim/attached`` holds its offset in its body once, and a reader
resolves its ``/sim/site/<name>`` from the body's poses
(:func:`ffexp.recording.reader.load`). What a scenario derives from them (a
funnel's errors) it records itself.
"""

from __future__ import annotations

from drivers.base.topics import CdrTopic, FieldSpec, JsonTopic, MessageSpec

F = FieldSpec


TRUTH = MessageSpec(
    "ffexp_msgs/msg/SimTruth",
    (
        F("contact_wrench", "float64", 6, "N, N m", "true wrench of the environment on the "
          "tool, TCF"),
        F("tcp_twist", "float64", 6, "m/s, rad/s", "true TCP twist, TCF"),
        F("in_contact", "uint8"),
    ),
    "Ground truth that only the simulator has: the tool's contact and motion.",
)

BODY = MessageSpec(
    "ffexp_msgs/msg/BodyState",
    (
        F("pose", "float64", 16, "m", "body frame in the world, 4x4 row-major"),
        F("twist", "float64", 6, "m/s, rad/s",
          "velocity of the body frame's origin and angular velocity, world coordinates"),
        F("mass_kg", "float64", 1, "kg", "the body's own mass"),
    ),
    "A free-moving body of the simulated scene (simulator only).",
)

SITE = MessageSpec(
    "ffexp_msgs/msg/Frame",
    (F("pose", "float64", 16, "m", "the frame in the world, 4x4 row-major"),),
    "A named frame of the simulated scene (simulator only).",
)

ATTACHED = JsonTopic(
    "/sim/attached",
    "ffexp.AttachedFrames",
    {
        "title": "ffexp.AttachedFrames",
        "type": "object",
        "properties": {"frames": {
            "type": "object",
            "description": "per named frame: the free body it is fixed on and its pose in "
                           "that body's frame",
            "additionalProperties": {
                "type": "object",
                "properties": {
                    "body": {"type": "string"},
                    "offset": {"type": "array", "items": {"type": "number"},
                               "minItems": 16, "maxItems": 16,
                               "description": "4x4 row-major [m]"},
                },
                "required": ["body", "offset"],
            },
        }},
        "required": ["frames"],
    },
    "once, at the first cycle, simulator only",
    "The named frames fixed on a free body (funnel_mouth on the target): their "
    "/sim/site/<name> is the body's pose times this offset, resolved on reading.",
)

#: ``/*``: one topic per body or frame of the scene, by its name (``/sim/body/target``,
#: ``/sim/body/chaser``, ``/sim/site/tcp``, an object's frame on a fixed body). The
#: back-end's ``topics`` (this name) holds the JSON topic of the attached frames too.
CDR_TOPICS: tuple[CdrTopic | JsonTopic, ...] = (
    CdrTopic("/sim/truth", TRUTH, "every controller cycle, simulator only"),
    CdrTopic("/sim/body/*", BODY, "every controller cycle, simulator only: one per free body"),
    CdrTopic("/sim/site/*", SITE, "every controller cycle, simulator only: one per named "
             "frame on no free body (those on one: resolved from /sim/attached)"),
    ATTACHED,
)
