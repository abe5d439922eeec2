"""Robot-neutral data exchanged between the experiment and any device back-end.

Plain dataclasses holding numpy arrays (no validation per cycle), in ffexp's
conventions (``docs/conventions.md``):

* poses are 4x4 homogeneous matrices in the robot's base frame, translation in m;
* wrenches are ``[fx, fy, fz, tx, ty, tz]`` in the tool frame (TCF) at the TCP,
  in N and N m; a measured wrench is what the environment exerts on the tool;
* twists are ``[vx, vy, vz, wx, wy, wz]`` in the TCF, in m/s and rad/s;
* Cartesian stiffness and damping are per TCF axis ``[x, y, z, rx, ry, rz]``.

Nothing here is specific to one robot or link: what only one back-end has
(FRI's packet fields, a simulator's ground truth) travels in
:attr:`RobotState.extras` / :attr:`AppliedCommand.extras`, typed by that
back-end, or in :attr:`RobotState.truth` (simulators only).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntFlag

import numpy as np
from numpy.typing import NDArray

#: A float64 numpy array: the project's one array alias (its tuple and number aliases,
#: ``Vec3``, ``Vec6``, ``PosFloat``, ..., are :mod:`drivers.config`'s, light).
F64 = NDArray[np.float64]

#: Nanoseconds per second: the one definition (log times are integer ns).
NS_PER_S = 1_000_000_000


def _zeros(n: int) -> F64:
    return np.zeros(n, dtype=np.float64)


_EYE4 = np.eye(4, dtype=np.float64)


def _eye4() -> F64:
    return _EYE4.copy()  # (a copy of one identity: np.eye costs more per call)


class FtStatus(IntFlag):
    """Status word of an F/T sample (Net F/T RDT bits; 0 = healthy); see the fact sheet."""

    OK = 0
    MONITOR_LATCHED = 0x00010000
    SATURATION = 0x00020000
    ERROR = 0x80000000


class Extras:
    """Base of back-end specific data carried beside the neutral fields.

    Each back-end subclasses it (FRI: the whole ``tFriMsrData``; the wire
    command). The run log records an extras object on the topics it names in
    :meth:`topics`, filling each topic's fields from same-named attributes.
    """

    def topics(self) -> tuple[str, ...]:
        """Recording topics whose fields are attributes of this object."""
        return ()

    def take_events(self) -> list[tuple[int, str, str, str]]:
        """The back-end's notes on its link since the last call (``(robot time [ns],
        level, name, message)``: state and quality changes, foreign senders), which the
        run logs as events; it forgets them. None by default."""
        return []


@dataclass
class BodyTruth:
    """One free-moving body of a simulated scene (the target, a floating base, ...)."""

    pose: F64 = field(default_factory=_eye4)
    """4x4 pose of the body frame in the world frame [m]."""
    twist: F64 = field(default_factory=lambda: _zeros(6))
    """``[vx, vy, vz, wx, wy, wz]``: the body frame origin's velocity and the angular
    velocity, both in world coordinates [m/s, rad/s]."""
    mass_kg: float = 0.0
    """The body's own mass (not what it carries; a rendered target's mock-up reports the
    rendered body's, ``carrier.render_target``)."""


@dataclass(frozen=True)
class AttachedFrame:
    """A named frame fixed on a free body: its pose follows the body's, so a recording
    keeps it once, as this offset, beside the body's pose of every cycle."""

    body: str
    """The free body it is fixed on (a name of :attr:`GroundTruth.bodies`)."""
    offset: F64
    """4x4 pose of the frame in the body's frame [m]."""

    def resolve(self, body_pose: F64) -> F64:
        """The frame's 4x4 pose from its body's (``body_pose`` may be ``(n, 4, 4)``)."""
        out: F64 = body_pose @ self.offset
        return out


@dataclass
class GroundTruth:
    """What only a simulator knows, attached to a robot state (``None`` on hardware).

    Neutral: every free-moving body of the scene by name (``"target"``, ``"base"``,
    ...), named frames on them (``"funnel_mouth"``), the true contact wrench on the
    tool and the true TCP twist. What a task makes of them (a funnel's lateral
    error, an insertion depth) is the scenario's (:mod:`ffexp.scenarios`). World
    frame: z up. The back-end that makes it names its recording topics
    (:meth:`messages`).
    """

    bodies: dict[str, BodyTruth] = field(default_factory=dict)
    sites: dict[str, F64] = field(default_factory=dict)
    """Named frames, 4x4 in the world frame [m] (those of :attr:`attached` too)."""
    attached: dict[str, AttachedFrame] = field(default_factory=dict)
    """The named frames fixed on one of :attr:`bodies`, by name: recorded once as their
    offset (:meth:`attached_message`), not every cycle. The same dict every cycle of a
    run (the run log writes it again only when it is another)."""
    contact_wrench: F64 = field(default_factory=lambda: _zeros(6))
    """True wrench the environment exerts on the tool, TCF at the TCP [N, N m]."""
    in_contact: bool = False
    tcp_twist: F64 = field(default_factory=lambda: _zeros(6))
    """True TCP twist ``[v, w]`` in the TCF [m/s, rad/s]."""
    base_pose: F64 | None = None
    """The robot's base frame in the world, 4x4, when it moves (a floating base);
    ``None``: the base frame is the world frame."""
    topic_prefix: str = "/sim"
    """The recording topics: ``<prefix>/truth``, ``<prefix>/body/<name>``,
    ``<prefix>/site/<name>`` (declared by the back-end that makes the truth)."""

    def body(self, name: str) -> BodyTruth | None:
        """The body ``name`` (``None``: the scene has none)."""
        return self.bodies.get(name)

    def messages(self) -> list[tuple[str, object]]:
        """``(topic, source)`` of every recording message of this cycle's truth: each
        source's attributes are its topic's fields by name. The frames of
        :attr:`attached` are not among them (:meth:`attached_message`)."""
        pre = self.topic_prefix
        names = _TOPIC_NAMES.get(pre)
        if names is None:
            names = _TOPIC_NAMES[pre] = (f"{pre}/truth", {}, {})
        out: list[tuple[str, object]] = [(names[0], self)]
        # (plain loops: a comprehension is a function call of its own, every cycle; the
        # topics' names made once per prefix and name)
        body_topics = names[1]
        for name, body in self.bodies.items():
            topic = body_topics.get(name)
            if topic is None:
                topic = body_topics[name] = f"{pre}/body/{name}"
            out.append((topic, body))
        if self.sites:
            attached = self.attached
            site_topics = names[2]
            for name, pose in self.sites.items():
                if name not in attached:
                    topic = site_topics.get(name)
                    if topic is None:
                        topic = site_topics[name] = f"{pre}/site/{name}"
                    out.append((topic, _Frame(pose)))
        return out

    def attached_message(self) -> tuple[str, dict[str, object]] | None:
        """``(topic, message)`` of :attr:`attached` as JSON: ``{"frames": {name: {"body":
        ..., "offset": 16 numbers, row-major}}}`` (``None``: no attached frame). A reader
        resolves each frame's ``<prefix>/site/<name>`` from ``<prefix>/body/<body>``."""
        if not self.attached:
            return None
        return f"{self.topic_prefix}/attached", {"frames": {
            name: {"body": a.body, "offset": a.offset.reshape(-1).tolist()}
            for name, a in self.attached.items()}}


#: Per topic prefix, the topics of :meth:`GroundTruth.messages`: the truth's, and per
#: name a body's and a site's (made once each).
_TOPIC_NAMES: dict[str, tuple[str, dict[str, str], dict[str, str]]] = {}


@dataclass
class _Frame:
    """A named frame as a recording message's source (its field ``pose``)."""

    pose: F64


@dataclass
class LinkHealth:
    """The link to the robot as the experiment needs to know it, this cycle."""

    commanding: bool = True
    """The robot applies the commands it receives (FRI: state CMD)."""
    healthy: bool = True
    """The link's quality allows commanding (FRI: quality above UNACCEPTABLE)."""
    cycle: int = 0
    """The robot's cycle counter (unbounded)."""
    cycle_s: float = 0.005
    """The robot's control cycle [s]."""


@dataclass
class RobotState:
    """One cycle of a robot, robot-neutral.

    ``time_ns`` is the robot's clock (simulated time, or the controller's
    timestamp); the experiment's log time is derived from it.
    """

    time_ns: int = 0
    tcp_pose_m: F64 = field(default_factory=_eye4)
    """Measured TCP pose, 4x4 in the base frame [m]."""
    joint_pos_rad: F64 = field(default_factory=lambda: _zeros(7))
    """Measured joint positions, as many as the robot has [rad]."""
    link: LinkHealth = field(default_factory=LinkHealth)
    tcp_twist_mps_radps: F64 | None = None
    """Measured TCP twist in the TCF, when the robot reports one [m/s, rad/s]."""
    ext_wrench_n_nm: F64 | None = None
    """The robot's own estimate of the external wrench on the tool, TCF at the TCP,
    when it has one (FRI: estExtTcpFT) [N, N m]."""
    truth: GroundTruth | None = None
    extras: Extras | None = None
    """Back-end specific data (FRI: the whole measurement packet)."""


@dataclass
class CartesianCommand:
    """A Cartesian impedance command: a spring-damper towards a set-point plus a wrench.

    The robot's controller applies ``K (pose - x) - D x' + wrench`` at the TCP.
    ``damping_ratio`` is normalised (0..1, as the KRC takes it). The caller may
    reuse and change a command after :meth:`RobotDriver.send` returns: a driver
    copies whatever it keeps.
    """

    pose_m: F64 = field(default_factory=_eye4)
    """Set-point, 4x4 in the base frame [m]."""
    stiffness_npm_nmprad: F64 = field(default_factory=lambda: _zeros(6))
    """Per TCF axis [N/m, N m/rad]."""
    damping_ratio: F64 = field(default_factory=lambda: _zeros(6))
    """Per TCF axis, normalised."""
    wrench_n_nm: F64 = field(default_factory=lambda: _zeros(6))
    """Superposed wrench, TCF at the TCP [N, N m]."""

    def copy(self) -> CartesianCommand:
        return CartesianCommand(
            self.pose_m.copy(),
            self.stiffness_npm_nmprad.copy(),
            self.damping_ratio.copy(),
            self.wrench_n_nm.copy(),
        )


class ApplyStatus(IntFlag):
    """How a command was applied, beside what was asked."""

    APPLIED = 0
    HELD = 0x1
    """No command was given: the robot kept its own set-point."""
    MIRRORED = 0x2
    """The robot was not commanding: the driver sent the robot's own set-point back."""
    CLIPPED = 0x4
    """A value was beyond the robot's limits and was clipped."""
    LATE = 0x8
    """The answer missed its deadline: the robot repeated the previous command."""


@dataclass
class AppliedCommand:
    """What a driver really sent (or will apply) for one cycle, beside the intent.

    ``command`` holds the values the robot applies after mirroring and
    clipping; ``status`` says what happened to the intent; ``extras`` is the
    back-end's own form (FRI: the ``tFriCmdData`` fields).
    """

    command: CartesianCommand = field(default_factory=CartesianCommand)
    status: ApplyStatus = ApplyStatus.APPLIED
    extras: Extras | None = None


@dataclass
class FtSamples:
    """F/T samples since the last read, oldest first.

    ``wrench`` is the sensor's reading in our sign convention (the wrench the
    environment exerts on the tool, TCF, referred to the TCP), *including* the
    sensor's bias and the tool's gravity and inertia load, like a real Net F/T
    after its tool transform. Compensation is the estimator's job.
    """

    time_ns: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    seq: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    wrench: F64 = field(default_factory=lambda: np.zeros((0, 6)))
    status: NDArray[np.uint32] = field(default_factory=lambda: np.zeros(0, dtype=np.uint32))

    def __len__(self) -> int:
        return int(self.time_ns.shape[0])

    @classmethod
    def concat(cls, parts: list[FtSamples]) -> FtSamples:
        if not parts:
            return cls()
        if len(parts) == 1:
            return parts[0]
        return cls(
            time_ns=np.concatenate([p.time_ns for p in parts]),
            seq=np.concatenate([p.seq for p in parts]),
            wrench=np.concatenate([p.wrench for p in parts]),
            status=np.concatenate([p.status for p in parts]),
        )


@dataclass
class TargetObservation:
    """The floating target's pose as a tracker last saw it (a camera, or a simulator).

    ``time_ns`` is when the pose was true (the frame's exposure, on the same
    clock as :attr:`RobotState.time_ns`), not when it arrived; a consumer
    judges staleness from it. ``valid`` is false when the tracker has no pose
    (marker not seen, stream lost); ``pose_m`` then holds the last valid one.
    """

    time_ns: int = 0
    pose_m: F64 = field(default_factory=_eye4)
    """Target block frame in the robot's base frame (4x4, m)."""
    mouth_m: F64 = field(default_factory=_eye4)
    """The target funnel's mouth frame in the base frame (4x4, m; x along the funnel
    axis into the target, see :mod:`drivers.base.placement`): ``pose_m`` times the
    tracker's known offset of the mouth on the target."""
    valid: bool = False
    source: str = ""
    """Which tracker produced it: ``"camera"``, ``"sim"``, ..."""
    frames: int = 0
    """Poses received since the tracker started (a counter, for drop statistics)."""
    status: str = ""
    """Why there is no pose when ``valid`` is false (``"marker not found"``,
    ``"stream lost: ..."``); empty otherwise."""
