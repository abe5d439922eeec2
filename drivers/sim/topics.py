"""The simulator's recording topics: its ground truth (:class:`~drivers.base.types.GroundTruth`).

Neutral: the truth's own fields on ``/sim/truth``, every free-moving body of the
scene on ``/sim/body/<name>`` and every named frame on ``/sim/site/<name>`` (a topic
name ending in ``/*`` stands for every topic of that prefix with one more name).
What a scenario derives from them (a funnel's errors) it records itself.
"""

from __future__ import annotations

from drivers.base.topics import CdrTopic, FieldSpec, MessageSpec

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

#: ``/*``: one topic per body or frame of the scene, by its name (``/sim/body/target``,
#: ``/sim/body/chaser``, ``/sim/site/funnel_mouth``, ``/sim/site/tcp``, an object's).
CDR_TOPICS: tuple[CdrTopic, ...] = (
    CdrTopic("/sim/truth", TRUTH, "every controller cycle, simulator only"),
    CdrTopic("/sim/body/*", BODY, "every controller cycle, simulator only: one per free body"),
    CdrTopic("/sim/site/*", SITE, "every controller cycle, simulator only: one per named "
             "frame"),
)
