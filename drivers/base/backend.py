"""What a back-end contributes to a rig: the config model of each device it offers, how that
device opens, and the recording topics of its extras.

A back-end is one folder, ``drivers/<name>/``; its ``backend.py`` holds one
:class:`Backend` (``BACKEND``) and :mod:`drivers.registry` lists it in one line.
From those entries the registry builds the rig's discriminated unions
(``[robot]``, ``[ft]``, ``[tracker]``, chosen by ``type``), the factory's
dispatch, the ``--driver`` and ``--ft`` names and the back-end topics of the
recording.

A device's config model (a :class:`DeviceConfig` with ``type: Literal[...]``)
is the rig table as the user writes it and is what its driver takes: no second
settings class, no field renamed on the way down. Errors name the rig's field
(``rigs/lwr4-lab.toml: robot.port: ...``). A field of type ``Path`` is
relative to the rig file (:func:`drivers.rig.load_rig` resolves it).

``backend.py`` stays light (pydantic models and these entries; no numpy, no
driver): each ``open`` imports its driver when it is called, so a run imports
only the back-ends its rig uses, and ``topics`` imports the topic definitions
when the recording asks for them.

A back-end also states what ``ffexp`` must know of it without naming it: the
counters of its link that are faults (:class:`LinkCounter`: a trial whose
counter grew while the method was in control is invalid), the statistics of
its link worth a run's summary (:class:`LinkStat`), and, for a simulated robot,
how it replays another robot's recordings open loop (:class:`Replay`: which
robots, where their recordings hold the applied commands, its own rig table).
A simulated robot states its scene before it opens (``RobotBackend.scene``)
and hands the same :class:`~drivers.description.scene.Scene` to the run
(``OpenedRobot.scene``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from importlib import import_module
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, Generic, Literal, TypeVar

from drivers.config import StrictModel

if TYPE_CHECKING:  # (annotations only: this module stays light, without numpy)
    from drivers.base.interfaces import ForceTorqueSensor, RobotDriver, TargetTracker
    from drivers.base.topics import CdrTopic, JsonTopic
    from drivers.description.scene import Scene

__all__ = [
    "Backend",
    "CommandFields",
    "DeviceConfig",
    "Emulator",
    "FtBackend",
    "LinkCounter",
    "LinkStat",
    "OpenContext",
    "OpenedRobot",
    "OpenedSensor",
    "OpenedTracker",
    "Replay",
    "RobotBackend",
    "TrackerBackend",
    "cdr_topics_of",
    "needs_offer",
    "needs_robot",
    "offering",
]


class DeviceConfig(StrictModel):
    """A rig table (``[robot]``, ``[ft]`` or ``[tracker]``); ``type`` names its back-end.

    Each back-end's model narrows ``type`` to its ``Literal`` name.
    """

    type: str
    offers: ClassVar[frozenset[str]] = frozenset()
    """What an opened robot of this table offers the rig's other devices (a robot table's
    class variable, not a field): ``world`` (it runs the simulated world in-process, whose
    target a ``sim`` tracker watches), ``world-ft`` (and leaves the world's F/T samples to
    a ``sim`` sensor), ``netft-host`` (an F/T box at the robot's address answers there).
    Devices ask for an offer (:func:`needs_offer`), never for another back-end's type."""


C = TypeVar("C", bound=DeviceConfig)


@dataclass(frozen=True)
class OpenContext:
    """What every ``open`` gets besides its own table."""

    source: str
    """The rig file (or ``"<built-in sim rig>"``): errors name ``<source>: <table>.<field>``."""
    scene_file: Path
    """The protocol's scene (a simulator uses it unless its rig table names one)."""
    scene_overrides: tuple[str, ...] = ()
    """``dotted.key=value`` overrides of the scene."""
    seed: int = 0
    """The run's seed (world and mock noise)."""

    def where(self, table: str) -> str:
        """How errors name a table of this rig: ``"<source>: <table>"``."""
        return f"{self.source}: {table}"

    def scene_path(self, rig_scene_file: Path | None) -> Path:
        """The scene a simulated robot runs in: its rig table's ``scene_file`` if it names
        one, else the protocol's."""
        return rig_scene_file if rig_scene_file is not None else self.scene_file


@dataclass
class OpenedRobot:
    """An opened robot and what its sensor, its tracker and the recording need from it."""

    robot: RobotDriver
    clock: Callable[[], int | None]
    """The robot's time [ns] (``None`` while unknown): what its F/T samples are stamped in."""
    host: str | None = None
    """The robot's address: an F/T box on the same host defaults to it (``ffexp emulate``)."""
    metadata: dict[str, str] = field(default_factory=dict)
    """Run metadata (``driver`` first: the robot's rig type)."""
    attachments: list[tuple[str, bytes]] = field(default_factory=list)
    """Files the recording attaches (name, bytes): the sim's scene TOML."""
    notice: str | None = None
    """One line for the user (where a link listens); the sensor's note is appended."""
    scene: Scene | None = None
    """The scene a simulated robot runs in (the one its ``RobotBackend.scene`` states);
    ``None``: a real robot, whose scene is the protocol's file."""


@dataclass
class OpenedSensor:
    """An opened F/T sensor, its run metadata and its note for the robot's notice."""

    sensor: ForceTorqueSensor
    metadata: dict[str, str] = field(default_factory=dict)
    note: str = ""
    """How the user's notice names it (``"Net F/T at 127.0.0.1:49152"``); empty: by type."""


@dataclass
class OpenedTracker:
    """An opened target tracker (``None``: the rig has none) and its run metadata."""

    tracker: TargetTracker | None
    metadata: dict[str, str] = field(default_factory=dict)


def _any_robot(cfg: Any, robot: DeviceConfig) -> str | None:
    return None


def needs_robot(table: str, *types: str, hint: str = ""
                ) -> Callable[[Any, DeviceConfig], str | None]:
    """A device's ``check``: it goes only with a robot of one of ``types``; otherwise one
    line, ``<table>.type '<its type>' needs robot.type 'a' or 'b'``, then `` (<hint>)``."""
    wanted = " or ".join(f"'{t}'" for t in types)
    why = f" ({hint})" if hint else ""

    def check(cfg: Any, robot: DeviceConfig) -> str | None:
        if robot.type in types:
            return None
        return f"{table}.type '{cfg.type}' needs robot.type {wanted}{why}"

    return check


def needs_offer(table: str, offer: str, hint: str = ""
                ) -> Callable[[Any, DeviceConfig], str | None]:
    """A device's ``check``: it goes only with a robot whose table :attr:`~DeviceConfig.offers`
    ``offer``; otherwise one line, ``<table>.type '<its type>' needs robot.type 'a' or 'b'``
    (the robot types that offer it, as far as they are known), then `` (<hint>)``."""
    why = f" ({hint})" if hint else ""

    def check(cfg: Any, robot: DeviceConfig) -> str | None:
        if offer in type(robot).offers:
            return None
        have = offering(offer)
        wanted = " or ".join(f"'{t}'" for t in have) if have else f"offering {offer!r}"
        return f"{table}.type '{cfg.type}' needs robot.type {wanted}{why}"

    return check


def offering(offer: str) -> list[str]:
    """The ``type`` of every registered robot whose table offers ``offer``, in the
    registry's order (read when asked: the registry is built from these entries)."""
    from drivers import registry

    return [t for t in registry.robot_types()
            if offer in registry.robot_backend(t).config.offers]


def cdr_topics_of(module: str) -> Callable[[], Sequence[CdrTopic]]:
    """A back-end's ``topics``: ``CDR_TOPICS`` of ``module``, imported when called."""
    def topics() -> Sequence[CdrTopic]:
        found: Sequence[CdrTopic] = import_module(module).CDR_TOPICS
        return found

    return topics


@dataclass(frozen=True)
class LinkCounter:
    """A cumulative counter a back-end records about its link: each increment is a fault.

    A trial is invalid when the counter grew while the method was in control
    (``ffexp.linkcheck``); a counter that goes back (a controller's restart) counts
    nothing for that step.
    """

    topic: str
    """The recording topic that holds it (``/robot/link_driver``)."""
    field: str
    """Its field on that topic (``lost``)."""
    meaning: str
    """What one increment is, plural, as a verdict names it (``measurements lost``)."""
    key: str = ""
    """The name verdicts and ``ffexp analyze --json`` give it; empty: ``field``."""

    @property
    def name(self) -> str:
        """The verdict's key for it."""
        return self.key or self.field


@dataclass(frozen=True)
class LinkStat:
    """A statistic of a back-end's link for a run's summary (``link`` of ``ffexp analyze``)."""

    name: str
    """Its key in the summary (``max_latency_s``)."""
    topic: str
    field: str
    reduce: Literal["count", "min", "max", "last", "fraction_below"]
    """``count``: messages on the topic; ``min``/``max``/``last`` of the field;
    ``fraction_below``: the fraction of messages whose field is below :attr:`below`."""
    below: float = 0.0


@dataclass(frozen=True)
class CommandFields:
    """Where a robot's recordings hold the Cartesian impedance command it applied, per
    cycle (the fields of one topic)."""

    topic: str
    pose: str
    """The set-point, 4x4 row-major in the base frame [m]."""
    stiffness: str
    """Per TCF axis ``[x, y, z, rx, ry, rz]`` [N/m, N m/rad]."""
    damping: str
    """Per TCF axis, normalised."""
    wrench: str
    """The superposed wrench, TCF at the TCP [N, N m]."""
    held: str = ""
    """A flags field whose :attr:`held_flag` bit marks a cycle the robot held on its own
    (the runner sent no command: ``send(None)``), replayed as such; empty: every cycle the
    robot commanded carries its command (FRI's packets)."""
    held_flag: int = 0


#: The runner's own record of the command a driver applied: ``/control/command``'s
#: ``applied_*`` fields, a cycle with bit 0 of ``status`` set held (``send(None)``). The
#: families whose commands cross no recorded wire (the UR's registers are written from
#: exactly these; the Franka's law runs in the driver) replay from it; a real rig's full
#: recording holds it as the simulator's does.
RUNNER_APPLIED = CommandFields("/control/command", pose="applied_pose",
                               stiffness="applied_stiffness", damping="applied_damping",
                               wrench="applied_wrench", held="status", held_flag=0x1)


@dataclass(frozen=True)
class Replay:
    """How a simulated robot replays, open loop, the commands another robot's recording
    holds (``ffexp calibrate``, ``ffexp resimulate``)."""

    robots: tuple[str, ...]
    """The ``[robot] type`` names whose recordings it replays."""
    commands: CommandFields
    """Where those recordings hold the applied commands."""
    table: Callable[[int, bool], dict[str, Any]]
    """Its own ``[robot]`` table for a replay: ``(cycles before the recorded robot first
    commanded, the commands crossed a float32 wire)``."""
    cycle_s: Callable[[Scene], float]
    """Its control cycle in a scene [s]."""
    wire: tuple[str, ...] = ()
    """Of :attr:`robots`, those whose commands always cross a float32 wire."""
    estimate_ft: tuple[str, ...] = ()
    """``[ft]`` types that are the robot's own wrench estimate (one sample a cycle, no
    sensor path), replayed as they are (their recorded table); any other F/T is replayed
    by the robot's ``default_ft``."""
    settings: tuple[str, ...] = ()
    """Fields of the recorded robot's ``[robot]`` table (the run's ``rig_json``) that its
    replay table takes over where the recording holds them: the driver's own settings,
    so a lab's rig replays as it ran; the others are the replay table's defaults."""


@dataclass(frozen=True)
class RobotBackend(Generic[C]):
    """A ``[robot] type``: its config model and how it opens."""

    config: type[C]
    """The ``[robot]`` table's model (``type: Literal["<name>"]``); the driver's argument."""
    open: Callable[[C, OpenContext], OpenedRobot]
    """Build the robot (UDP links bind their port at once: a port in use is one error line)."""
    driver: str
    """Its ``--driver`` name (the built-in rig of the command line)."""
    default_ft: str
    """The ``[ft] type`` of the built-in rig ``--driver`` builds."""
    scene: Callable[[C, OpenContext], Scene] | None = None
    """A simulated robot's scene from its table, known before it opens (what ``open``
    then puts on ``OpenedRobot.scene``); ``None``: a real robot."""
    replay: Replay | None = None
    """A simulated robot's way of replaying recordings; ``None``: it replays none."""
    arm: str | None = None
    """The arm its controller drives (a scene's ``arm.model``); ``None``: any (a mock)."""
    takes_arm_place: bool = False
    """It puts its arm in the place of a scene's other arm (the paper's rig with its
    arm swapped in, as ``ffexp emulate --robot`` serves it) rather than refusing it."""

    @property
    def rig_type(self) -> str:
        """The ``type`` the rig names it by."""
        return _type_of(self.config)


@dataclass(frozen=True)
class FtBackend(Generic[C]):
    """An ``[ft] type``: its config model, how it opens beside a robot, which robots suit it."""

    config: type[C]
    open: Callable[[C, OpenContext, OpenedRobot], OpenedSensor]
    check: Callable[[C, DeviceConfig], str | None] = _any_robot
    """One line if this sensor cannot go with the rig's robot (its table), else ``None``."""

    @property
    def rig_type(self) -> str:
        """The ``type`` the rig names it by."""
        return _type_of(self.config)


@dataclass(frozen=True)
class TrackerBackend(Generic[C]):
    """A ``[tracker] type``: its config model, how it opens beside a robot."""

    config: type[C]
    open: Callable[[C, OpenContext, OpenedRobot], OpenedTracker]
    check: Callable[[C, DeviceConfig], str | None] = _any_robot
    """One line if this tracker cannot go with the rig's robot (its table), else ``None``."""

    @property
    def rig_type(self) -> str:
        """The ``type`` the rig names it by."""
        return _type_of(self.config)


@dataclass(frozen=True)
class Backend:
    """One back-end folder's entry in :mod:`drivers.registry`."""

    name: str
    """The folder (``"fri"``), for messages."""
    robots: tuple[RobotBackend[Any], ...] = ()
    sensors: tuple[FtBackend[Any], ...] = ()
    trackers: tuple[TrackerBackend[Any], ...] = ()
    topics: Callable[[], Sequence[CdrTopic | JsonTopic]] = tuple
    """The recording topics of its extras (:meth:`drivers.base.types.Extras.topics`
    names them), imported when called."""
    link_faults: tuple[LinkCounter, ...] = ()
    """The counters of those topics that are link faults (they invalidate a trial)."""
    link_stats: tuple[LinkStat, ...] = ()
    """The statistics of those topics that summarise its link in a run's metrics."""
    emulators: tuple[Emulator, ...] = ()
    """The robot controllers of its family ``ffexp emulate --robot`` can serve."""


@dataclass(frozen=True)
class Emulator:
    """One robot controller a family's emulator serves (``ffexp emulate --robot <name>``).

    Light, like the rest of the entry: ``serve`` names the function (``module:name``) that
    builds the served controller on a simulated world, imported when the rig opens;
    :mod:`drivers.emulate.session` calls it and serves what it returns
    (:class:`drivers.emulate.served.ServedRobot`).
    """

    name: str
    """``--robot``'s name: also the scene's ``arm.model`` it serves."""
    what: str
    """One line for ``--help``."""
    serve: str
    """``module:function`` of ``(world, settings, ft_box) -> ServedRobot``."""
    listen: tuple[str, int] | None = None
    """Where it listens by default (its client opens the link); ``None``: it sends to the
    remote driver it is told of (``--remote``)."""
    overrides_from: str | None = None
    """``module:NAME`` of the scene overrides that put this arm in the paper's rig (None:
    the paper's rig as it is); read when asked, so the command line's start stays light."""
    takes_cycle: bool = False
    """Its cycle is set on the command line (FRI's friOpen); else the scene's."""
    ft_box: bool = False
    """The world's F/T sensor is served beside it as a Net F/T box (else its wrench goes
    over its own link)."""
    faults: tuple[tuple[str, str], ...] = ()
    """Its own faults, ``(name, what)``: ``--fault name=value`` (a number)."""
    camera: bool = False
    """The camera above the bed may be served beside it (it calls the rig back between
    its world steps, when the camera renders)."""
    serve_joint: str | None = None
    """``module:function`` of ``(shared_world, role, joints, host, port, cycle_s) -> server``:
    one arm of a shared two-arm world behind this controller's link, joint positions in
    lockstep (:mod:`drivers.emulate.twoarm`); ``None``: it serves no such arm."""
    joint_link: str | None = None
    """``module:class`` of the client side, ``(role, host, port, joints) -> JointLink``
    (:class:`drivers.carrier.plant.JointLink`)."""

    @property
    def needs_remote(self) -> bool:
        """It sends to a remote driver (``--remote``) rather than listening."""
        return self.listen is None

    def scene_overrides(self) -> tuple[str, ...]:
        """The default scene: the paper's rig with these overrides."""
        if self.overrides_from is None:
            return ()
        module, name = self.overrides_from.split(":")
        return tuple(getattr(import_module(module), name))


def _type_of(model: type[DeviceConfig]) -> str:
    default = model.model_fields["type"].default
    if not isinstance(default, str):
        raise TypeError(f"{model.__name__}: type needs a Literal default (its rig name)")
    return default
