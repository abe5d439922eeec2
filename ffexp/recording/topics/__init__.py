"""Every topic of an ffexp run recording, its message type and fields: the one
place they are defined and documented (``ffexp topics`` prints this as text).

Encodings:

- high-rate numeric topics: ROS 2 ``ros2msg`` schemas with ``cdr`` message
  encoding, flat fixed-size messages (see :mod:`ffexp.recording.schema`);
  measured in ``benchmarks/bench_recording.py``: encoding is a numpy
  ``tobytes()`` (about a microsecond) where ``json.dumps`` of the same
  measurement costs tens, and ``load`` decodes a topic with one
  ``np.frombuffer`` instead of parsing every message;
- low-rate topics (events, phases, transforms): JSON with a JSON schema,
  using Foxglove's well-known schema names (``foxglove.Log``,
  ``foxglove.FrameTransform``) so its panels pick them up.

Units are SI; wrenches ``[fx, fy, fz, tx, ty, tz]`` in the tool frame (TCF),
measured wrench = what the environment exerts on the tool; 4x4 poses are
stored row-major as 16 numbers; log times are integer nanoseconds.

A back-end's extras (FRI's measurement, link and command packets) are recorded
on the topics its folder defines (``drivers/fri/topics.py``); they are taken
here from :mod:`drivers.registry`, so a new back-end edits no ``ffexp`` module.
"""

from __future__ import annotations

from typing import Any

from drivers import registry
from ffexp import scenarios
from ffexp.recording.schema import (
    QUAT_SCHEMA,
    TIME_SCHEMA,
    VEC3_SCHEMA,
    CdrTopic,
    FieldSpec,
    JsonTopic,
    MessageSpec,
)
from ffexp.recording.topics import scene as topics_scene
from ffexp.recording.topics import target as topics_target

F = FieldSpec



#: Joints a ``/robot/state`` message holds (a robot with fewer pads with NaN).
STATE_JOINTS = 7

ROBOT_STATE = MessageSpec(
    "ffexp_msgs/msg/RobotState",
    (
        F("time_ns", "int64", 1, "ns", "the robot's clock (simulated time or controller stamp)"),
        F("tcp_pose", "float64", 16, "m", "measured TCP pose in the base frame, 4x4 row-major"),
        F("joint_pos", "float64", STATE_JOINTS, "rad", "measured joint positions (NaN: none)"),
        F("n_joints", "uint8", 1, "", "joints the robot has"),
        F("commanding", "uint8", 1, "", "the robot applies commands (FRI: CMD)"),
        F("healthy", "uint8", 1, "", "the link's quality allows commanding"),
        F("cycle", "int64", 1, "", "the robot's cycle counter"),
        F("cycle_s", "float64", 1, "s", "the robot's control cycle"),
        F("has_twist", "uint8", 1, "", "the robot reported a TCP twist"),
        F("twist", "float64", 6, "m/s, rad/s", "measured TCP twist, TCF (0 when none)"),
        F("has_ext_wrench", "uint8", 1, "", "the robot reported an external wrench"),
        F("ext_wrench", "float64", 6, "N, N m", "the robot's external wrench estimate, TCF"),
    ),
    "The robot-neutral state the loop got this cycle (drivers.base.RobotState), "
    "enough to feed the cycle again (ffexp replay).",
)

FT_SAMPLE = MessageSpec(
    "ffexp_msgs/msg/FtSample",
    (
        F("wrench", "float64", 6, "N, N m", "raw reading, environment on tool, TCF"),
        F("seq", "uint32", 1, "", "sensor sample counter"),
        F("status", "uint32", 1, "", "Net F/T status word (0x00020000 saturation)"),
    ),
    "Every F/T sample at the sensor's rate (log time = sample time).",
)

ESTIMATE = MessageSpec(
    "ffexp_msgs/msg/Estimate",
    (
        F("wrench", "float64", 6, "N, N m", "filtered, bias and tool load removed, TCF"),
        F("wrench_std", "float64", 6, "N, N m", "1-sigma of wrench"),
        F("bias", "float64", 6, "N, N m", "estimated sensor bias"),
        F("twist_tcf", "float64", 6, "m/s, rad/s", "tool twist in TCF (motion filter)"),
        F("f_z", "float64", 1, "N", "contact force along the approach axis, -wrench[2]"),
        F("n_samples", "uint32", 1, "", "F/T samples that arrived in this cycle"),
        F("in_contact", "uint8", 1, "", "contact detector state"),
    ),
    "Estimator state per controller cycle.",
)

CONTROL = MessageSpec(
    "ffexp_msgs/msg/ControlTerms",
    (
        F("p", "float64", 6, "N, N m", "proportional term of the force loop"),
        F("i", "float64", 6, "N, N m", "integral term of the force loop"),
        F("ri", "float64", 6, "N, N m", "apparent inertia reduction K_RI w"),
        F("ff", "float64", 6, "N, N m", "contact-force feedforward on the force axes, eq. (2)"),
        F("impedance", "float64", 6, "N, N m", "external impedance law"),
        F("total", "float64", 6, "N, N m", "superposed wrench sent (addTcpFT), TCF"),
        F("f_ref", "float64", 6, "N, N m", "force reference"),
        F("setpoint", "float64", 16, "m", "impedance set-point, 4x4 row-major"),
        F("phase", "int32", 1, "", "runner phase id (see /runner/phase)"),
        F("saturated", "uint8"),
    ),
    "Controller terms per cycle.",
)


INTENT = MessageSpec(
    "ffexp_msgs/msg/CartesianCommand",
    (
        F("pose", "float64", 16, "m", "the runner's set-point, 4x4 row-major (0 if not given)"),
        F("stiffness", "float64", 6, "N/m, N m/rad", "asked, x y z rx ry rz (TCF)"),
        F("damping", "float64", 6, "", "asked, normalised"),
        F("wrench", "float64", 6, "N, N m", "asked superposed wrench, TCF"),
        F("applied_pose", "float64", 16, "m", "what the robot gets, after mirroring/clipping"),
        F("applied_stiffness", "float64", 6, "N/m, N m/rad"),
        F("applied_damping", "float64", 6, ""),
        F("applied_wrench", "float64", 6, "N, N m"),
        F("status", "uint32", 1, "", "1 held, 2 mirrored, 4 clipped, 8 late (flags)"),
        F("given", "uint8", 1, "", "0: the runner asked the robot to keep its own set-point"),
    ),
    "The runner's intent beside the command the driver really applied, every cycle.",
)

ADMITTANCE = MessageSpec(
    "ffexp_msgs/msg/AdmittanceTerms",
    (
        F("drive", "float64", 6, "N, N m", "W (F_ref - F_c) + (I - W) w on the admittance axes"),
        F("velocity", "float64", 6, "m/s, rad/s", "virtual set-point velocity (entry TCF)"),
        F("displacement", "float64", 6, "m, rad", "virtual set-point offset (entry TCF)"),
    ),
    "The admittance method's virtual mass-damper, every cycle in ALIGN.",
)

#: The core topics before the back-ends' (kept in this order: ``ffexp topics`` lists them so).
_CDR_HEAD = (CdrTopic("/robot/state", ROBOT_STATE, "every controller cycle"),)
_CDR_CORE = (
    CdrTopic("/control/command", INTENT, "every controller cycle"),
    CdrTopic("/control/admittance", ADMITTANCE, "every cycle in ALIGN, admittance method"),
    CdrTopic("/ft/raw", FT_SAMPLE, "every sensor sample"),
    CdrTopic("/estimator/state", ESTIMATE, "every controller cycle"),
    CdrTopic("/control/terms", CONTROL, "every controller cycle"),
    *topics_target.CDR, *topics_scene.CDR,
)

LOG_LEVELS = {"DEBUG": 1, "INFO": 2, "WARNING": 3, "ERROR": 4, "FATAL": 5}

_NUM_OR_NULL: dict[str, Any] = {"type": ["number", "null"]}

FRICTION_TRACK_SCHEMA: dict[str, Any] = {
    "title": "ffexp.friction.TrackSample",
    "type": "object",
    "properties": {
        "frame": {"type": "integer"},
        "t_s": {"type": "number"},
        "valid": {"type": "boolean"},
        "in_window": {"type": "boolean"},
        "u_px": _NUM_OR_NULL,
        "v_px": _NUM_OR_NULL,
        "x_m": _NUM_OR_NULL,
        "y_m": _NUM_OR_NULL,
        "s_m": {**_NUM_OR_NULL, "description": "position along the motion direction"},
    },
    "required": ["frame", "t_s", "valid"],
}

FRICTION_RESULT_SCHEMA: dict[str, Any] = {
    "title": "ffexp.friction.Result",
    "type": "object",
    "properties": {
        "mu": {"type": "number"},
        "mu_std": {"type": "number"},
        "mu_upper_bound": {"type": "number"},
        "significant": {"type": "boolean"},
        "decel_mps2": {"type": "number"},
        "v0_mps": {"type": "number"},
        "window_s": {"type": "number"},
        "frames_used": {"type": "integer"},
    },
    "required": ["mu", "mu_std", "mu_upper_bound", "significant", "decel_mps2"],
}

_JSON_CORE = (
    JsonTopic(
        "/events",
        "foxglove.Log",
        {
            "title": "foxglove.Log",
            "type": "object",
            "properties": {
                "timestamp": TIME_SCHEMA,
                "level": {"type": "integer", "description": "1 debug .. 5 fatal"},
                "message": {"type": "string"},
                "name": {"type": "string", "description": "event kind"},
                "file": {"type": "string"},
                "line": {"type": "integer"},
            },
        },
        "on event",
        "Phase changes, contact made/broken, aborts, faults; name = event kind.",
    ),
    JsonTopic(
        "/tf",
        "foxglove.FrameTransform",
        {
            "title": "foxglove.FrameTransform",
            "type": "object",
            "properties": {
                "timestamp": TIME_SCHEMA,
                "parent_frame_id": {"type": "string"},
                "child_frame_id": {"type": "string"},
                "translation": VEC3_SCHEMA,
                "rotation": QUAT_SCHEMA,
            },
        },
        "every 20 ms of run time per frame",
        "Tool (TCP) in the robot base; target (sim truth), target_tracked (the tracker) "
        "or target_nominal (the start placement); link1..link7 of the arm, each in its "
        "parent; for the 3-D panel with /scene/rig.",
    ),
    JsonTopic(
        "/runner/phase",
        "ffexp.Phase",
        {
            "title": "ffexp.Phase",
            "type": "object",
            "properties": {
                "phase": {"type": "string"},
                "phase_id": {"type": "integer", "description": "ffexp.contracts.Phase"},
                "reason": {"type": "string", "description": "one line for people"},
                "stop_reason": {
                    "type": "string",
                    "description": "ffexp.contracts.StopReason value on DONE/ABORT, else ''",
                },
                "aligned": {"type": "boolean", "description": "the run ended aligned"},
            },
        },
        "on phase change",
        "Runner phase: CONNECT, APPROACH, ALIGN, DONE, ABORT, with the typed stop reason.",
    ),
    JsonTopic(
        "/friction/track",
        "ffexp.friction.TrackSample",
        FRICTION_TRACK_SCHEMA,
        "every video frame (friction recordings only)",
        "Tracked target per frame of `ffexp friction estimate`: pixel centre, "
        "metric position, position s_m along the motion; log time = frame time.",
    ),
    JsonTopic(
        "/friction/result",
        "ffexp.friction.Result",
        FRICTION_RESULT_SCHEMA,
        "once, at the end of the fit window (friction recordings only)",
        "The friction estimate: mu, its 1-sigma, the deceleration and the fit window.",
    ),
    *topics_target.JSON, *topics_scene.JSON,
)

class TopicTable(dict[str, CdrTopic]):
    """The CDR topics by name; a name ending in ``/*`` is a family: it stands for every
    topic of its prefix with one more name (``/sim/body/*``: ``/sim/body/target``, ...),
    as a back-end whose topics follow its scene declares them."""

    def family(self, topic: str) -> CdrTopic | None:
        """The family ``topic`` belongs to (``None``: none)."""
        head, _, name = topic.rpartition("/")
        if not name or name == "*":
            return None
        return dict.get(self, f"{head}/*")

    def __missing__(self, topic: str) -> CdrTopic:
        found = self.family(topic)
        if found is None:
            raise KeyError(topic)
        return found

    def __contains__(self, topic: object) -> bool:
        return dict.__contains__(self, topic) or (
            isinstance(topic, str) and self.family(topic) is not None)

    def get(self, topic: str, default: CdrTopic | None = None) -> CdrTopic | None:  # type: ignore[override]
        return self[topic] if topic in self else default


CDR_TOPICS: TopicTable = TopicTable()
JSON_TOPICS: dict[str, JsonTopic] = {}


def _collect() -> None:
    """Fill :data:`CDR_TOPICS` and :data:`JSON_TOPICS` (in place) from the core topics and
    the back-ends' (:mod:`drivers.registry`); again whenever the registry changes."""
    cdr: tuple[CdrTopic, ...] = (*_CDR_HEAD, *registry.backend_cdr_topics(), *_CDR_CORE,
                                 *scenarios.scenario_topics())
    json_topics: tuple[JsonTopic, ...] = (*_JSON_CORE, *registry.backend_json_topics())
    names = [t.topic for t in cdr] + [t.topic for t in json_topics]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ValueError(f"recording topics defined twice: {', '.join(twice)}")
    CDR_TOPICS.clear()
    CDR_TOPICS.update((t.topic, t) for t in cdr)
    JSON_TOPICS.clear()
    JSON_TOPICS.update((t.topic, t) for t in json_topics)


_collect()
registry.on_change(_collect)
scenarios.on_change(_collect)


def describe() -> str:
    """All topics and fields as text (the documentation of a recording)."""
    out = [__doc__ or "", ""]
    for t in CDR_TOPICS.values():
        out.append(f"{t.topic}  [{t.spec.name}, cdr, {t.rate}]  {t.spec.doc}")
        for f in t.spec.fields:
            arr = f"[{f.count}]" if f.count > 1 else ""
            unit = f" [{f.unit}]" if f.unit else ""
            out.append(f"    {f.type}{arr} {f.name}{unit}  {f.doc}".rstrip())
    for j in JSON_TOPICS.values():
        out.append(f"{j.topic}  [{j.schema_name}, json, {j.rate}]  {j.doc}")
        for name in j.schema["properties"]:
            out.append(f"    {name}")
    return "\n".join(out)


def topic_rows() -> list[dict[str, str]]:
    """One row per topic: topic, type, encoding, rate, what it holds (``ffexp topics``)."""
    rows = [
        {"topic": t.topic, "type": t.spec.name, "encoding": "cdr", "rate": t.rate,
         "doc": t.spec.doc}
        for t in CDR_TOPICS.values()
    ]
    rows += [
        {"topic": j.topic, "type": j.schema_name, "encoding": "json", "rate": j.rate,
         "doc": j.doc}
        for j in JSON_TOPICS.values()
    ]
    return rows


def field_rows() -> list[dict[str, str]]:
    """One row per field of every topic (``ffexp topics --fields``)."""
    rows = []
    for t in CDR_TOPICS.values():
        for f in t.spec.fields:
            arr = f"[{f.count}]" if f.count > 1 else ""
            rows.append({"topic": t.topic, "field": f.name, "type": f"{f.type}{arr}",
                         "unit": f.unit, "doc": f.doc})
    for j in JSON_TOPICS.values():
        for name, prop in j.schema["properties"].items():
            kind = prop.get("type", "object")
            rows.append({"topic": j.topic, "field": name,
                         "type": "|".join(kind) if isinstance(kind, list) else str(kind),
                         "unit": "", "doc": str(prop.get("description", ""))})
    return rows
