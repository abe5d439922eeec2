"""The recording topics of a rendered-target run (:mod:`drivers.carrier`): the loop's
state per carrier cycle and the contact's truth per fine step. Each device's topics
are under its own prefix (``/carrier/...``; the impact's truth under ``/hil/...``)."""

from __future__ import annotations

from drivers.base.topics import CdrTopic, FieldSpec, JsonTopic, MessageSpec

F = FieldSpec

__all__ = ["CARRIER_EVENT", "CARRIER_STATE", "HIL_CONTACT", "HIL_IDEAL", "TOPICS"]

STATE = MessageSpec(
    "ffexp_msgs/msg/CarrierState",
    (
        F("position", "float64", 3, "m", "rendered body's centre of mass, world"),
        F("rotvec", "float64", 3, "rad", "rendered body's orientation (rotation vector)"),
        F("twist", "float64", 6, "m/s, rad/s", "rendered body's twist, world"),
        F("flange", "float64", 3, "m", "the carrier flange's (mock-up's) position now"),
        F("wrench_measured", "float64", 6, "N, N m", "the F/T reading, weight and inertia "
          "compensated, world, about the mock-up's centre"),
        F("wrench_applied", "float64", 6, "N, N m", "the wrench the integrator used (delayed, "
          "plus the passivity controller's damping)"),
        F("closing_mps", "float64", 1, "m/s", "closing speed of tool and rendered body at "
          "the contact point"),
        F("generated_j", "float64", 1, "J", "passivity observer: energy the loop generated"),
        F("dissipated_j", "float64", 1, "J", "energy the passivity controller took out"),
        F("energy_j", "float64", 1, "J", "rendered kinetic energy in the chaser's frame"),
    ),
    "The micro-gravity emulator's loop, once per carrier cycle.",
)

CONTACT = MessageSpec(
    "ffexp_msgs/msg/ImpactContact",
    (
        F("depth_m", "float64", 1, "m", "penetration of tool tip into the mock-up's face"),
        F("force_n", "float64", 1, "N", "the contact's normal force"),
        F("normal_velocity_mps", "float64", 1, "m/s", "the mock-up's contact point along the "
          "normal"),
        F("tool_x_m", "float64", 1, "m", "the chaser tool tip's x"),
    ),
    "The impact's truth at the fine physics step.",
)

CARRIER_STATE = CdrTopic("/carrier/state", STATE, "carrier cycle")
HIL_IDEAL = CdrTopic("/hil/ideal", STATE, "carrier cycle (the same impact on the free body)")
HIL_CONTACT = CdrTopic("/hil/contact", CONTACT, "fine physics step")
CARRIER_EVENT = JsonTopic(
    "/carrier/event", "ffexp.DeviceEvent",
    {"type": "object", "properties": {"device": {"type": "string"},
                                      "cause": {"type": "string"},
                                      "t_s": {"type": "number"}}},
    "on event", "A device stopped the run: which device (carrier, chaser) and why.")

TOPICS = (CARRIER_STATE, HIL_IDEAL, HIL_CONTACT)
