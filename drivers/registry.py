"""The back-ends a rig may name: one line per back-end folder.

Each folder ``drivers/<name>/`` contributes one :class:`~drivers.base.backend.Backend`
(``BACKEND`` in its ``backend.py``): the config model and ``open`` of every device
it offers, its ``--driver`` name, and the recording topics of its extras. From
these entries come the rig's discriminated unions (:mod:`drivers.rig`), the
factory's dispatch (:mod:`drivers.factory`), the command line's ``--driver``
and ``--ft`` names, the back-end topics of the recording
(``ffexp.recording.topics``), the link-fault counters and link statistics
``ffexp`` reads from those topics (:func:`link_faults`, :func:`link_stats`) and
the simulated robot that replays a recording (:func:`replayer`). The ``none``
tracker (no tracker) is built in. A robot family is one folder: its real robot, its
simulated one in-process (the lockstep controller in front of the simulator's world,
``drivers/<family>/emulate/``), the controller ``ffexp emulate`` serves (:func:`emulators`)
and that controller's law on the simulated world (:mod:`drivers.world`, neutral); the
simulated world's sensor and tracker are :mod:`drivers.sim`'s.

:func:`register` adds a back-end at run time (a plug-in, a test's toy back-end);
the rig's unions are rebuilt from the registry then.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from importlib import import_module
from typing import TYPE_CHECKING, Annotated, Any, Literal

from pydantic import Field

from drivers.base.backend import (
    Backend,
    DeviceConfig,
    Emulator,
    FtBackend,
    LinkCounter,
    LinkStat,
    OpenContext,
    OpenedRobot,
    OpenedTracker,
    RobotBackend,
    TrackerBackend,
)

if TYPE_CHECKING:
    from drivers.base.topics import CdrTopic, JsonTopic

__all__ = [
    "DEFAULT_ROBOT",
    "FOLDERS",
    "NoTracker",
    "backend_cdr_topics",
    "backend_json_topics",
    "backends",
    "carrier_world",
    "driver_names",
    "emulator",
    "emulators",
    "ft_backend",
    "ft_types",
    "joint_link",
    "link_faults",
    "link_stats",
    "on_change",
    "register",
    "registered",
    "replayer",
    "robot_backend",
    "robot_for_driver",
    "robot_types",
    "serve_two_arms",
    "tracker_backend",
    "tracker_types",
    "union",
    "unregister",
]


class NoTracker(DeviceConfig):
    """No target tracker: the verdict comes from ground truth or the observer."""

    type: Literal["none"] = "none"


def _open_none(cfg: NoTracker, ctx: OpenContext, robot: OpenedRobot) -> OpenedTracker:
    return OpenedTracker(None)


_NONE = Backend("none", trackers=(TrackerBackend(NoTracker, _open_none),))

#: The shipped back-ends, one line per folder ``drivers/<name>/`` (its ``backend.py``
#: holds ``BACKEND``); the order is the order of the types in messages and schemas.
FOLDERS = (
    "fri",  # KUKA LWR4+: [robot] sim (in-process), fri1 (a KRC2 LR over FRI 1.x);
    #         [ft] fri-estimate; emulator lwr4
    "sim",  # [ft] sim, [tracker] sim: the simulator's sensor and camera model
    "netft",  # [ft] netft: an ATI Net F/T box
    "mock",  # [robot] mock, [ft] mock: scripted, for tests and dry runs
    "camera",  # [tracker] camera: a fiducial marker seen by a camera
    "ur",  # Universal Robots e-Series: [robot] ur (RTDE), ur-sim (in-process);
    #        [ft] ur-wrench; emulator ur5e
    "franka",  # Franka FR3 / Panda: [robot] franka (libfranka), franka-sim (in-process);
    #            [ft] franka-wrench; emulator fr3
)


#: The built-in rig's robot (a rig file without ``[robot]``): the paper's LWR4+, simulated;
#: its F/T sensor is the robot's ``default_ft``.
DEFAULT_ROBOT = "sim"


def _entry(folder: str) -> Backend:
    backend = import_module(f"drivers.{folder}.backend").BACKEND
    if not isinstance(backend, Backend):
        raise TypeError(f"drivers/{folder}/backend.py: BACKEND is not a Backend")
    return backend


_BACKENDS: list[Backend] = [_NONE, *(_entry(folder) for folder in FOLDERS)]

#: Called after :func:`register` changed the registry (the rig rebuilds its unions).
_listeners: list[Callable[[], None]] = []


def backends() -> tuple[Backend, ...]:
    """The registered back-ends, in order."""
    return tuple(_BACKENDS)


def _robots() -> dict[str, RobotBackend[Any]]:
    return {r.rig_type: r for b in _BACKENDS for r in b.robots}


def _sensors() -> dict[str, FtBackend[Any]]:
    return {s.rig_type: s for b in _BACKENDS for s in b.sensors}


def _trackers() -> dict[str, TrackerBackend[Any]]:
    return {t.rig_type: t for b in _BACKENDS for t in b.trackers}


def robot_types() -> tuple[str, ...]:
    """The ``[robot] type`` names."""
    return tuple(_robots())


def ft_types() -> tuple[str, ...]:
    """The ``[ft] type`` names (the command line's ``--ft``)."""
    return tuple(_sensors())


def tracker_types() -> tuple[str, ...]:
    """The ``[tracker] type`` names."""
    return tuple(_trackers())


def driver_names() -> tuple[str, ...]:
    """The command line's ``--driver`` names (one per robot back-end)."""
    return tuple(r.driver for r in _robots().values())


def robot_backend(type_: str) -> RobotBackend[Any]:
    """The robot back-end a rig's ``[robot] type`` names (KeyError if none)."""
    return _robots()[type_]


def ft_backend(type_: str) -> FtBackend[Any]:
    """The F/T back-end a rig's ``[ft] type`` names (KeyError if none)."""
    return _sensors()[type_]


def tracker_backend(type_: str) -> TrackerBackend[Any]:
    """The tracker back-end a rig's ``[tracker] type`` names (KeyError if none)."""
    return _trackers()[type_]


def robot_for_driver(driver: str) -> RobotBackend[Any] | None:
    """The robot back-end of a ``--driver`` name, or ``None``."""
    return next((r for r in _robots().values() if r.driver == driver), None)


def replayer(type_: str) -> RobotBackend[Any] | None:
    """The simulated robot that replays recordings of the ``[robot] type`` ``type_``
    (:class:`~drivers.base.backend.Replay`), or ``None``."""
    return next((r for r in _robots().values()
                 if r.replay is not None and type_ in r.replay.robots), None)


#: The world a simulated carrier arm and the chaser share (``carrier.model = "arm"``): the
#: simulator's (``module:class``, imported when asked).
CARRIER_WORLD = "drivers.world.twoarm:TwoArmWorld"


def carrier_world(scene: Any, layout: Any, seed: int = 0) -> Any:
    """The in-process two-arm world of a rendered-target impact
    (:class:`drivers.carrier.plant.CarrierPlant` on ``layout``)."""
    module, name = CARRIER_WORLD.split(":")
    return getattr(import_module(module), name)(scene, layout, seed)


#: The servers of a two-arm world, each arm behind its own emulator (``module:class``).
TWO_ARM_SERVERS = "drivers.emulate.twoarm:TwoArmServers"


def serve_two_arms(scene: Any, layout: Any, *, chaser: tuple[str, str, int],
                   carrier: tuple[str, str, int], seed: int = 0) -> Any:
    """Both arms of a two-arm world served, each by its emulator ``(name, host, port)``
    (:class:`drivers.emulate.twoarm.TwoArmServers`, a context manager)."""
    module, name = TWO_ARM_SERVERS.split(":")
    return getattr(import_module(module), name)(scene, layout, chaser=chaser,
                                                carrier=carrier, seed=seed)


def joint_link(emulator_name: str, role: str, host: str, port: int, joints: int) -> Any:
    """The client side of an emulator's arm of a shared world
    (:class:`drivers.carrier.plant.JointLink`), connected to ``host:port``.

    Raises:
        KeyError: no such emulator; ValueError: it serves no such arm.
    """
    entry = emulator(emulator_name)
    if entry.joint_link is None:
        raise ValueError(f"the {emulator_name} emulator serves no arm of a shared world")
    module, name = entry.joint_link.split(":")
    return getattr(import_module(module), name)(role, host, port, joints)


def emulators() -> tuple[Emulator, ...]:
    """The robot controllers ``ffexp emulate`` can serve, in registry order (the first is
    its default)."""
    return tuple(e for b in _BACKENDS for e in b.emulators)


def emulator(name: str) -> Emulator:
    """The emulated controller ``--robot name`` (KeyError if none)."""
    for e in emulators():
        if e.name == name:
            return e
    raise KeyError(name)


def link_faults() -> tuple[LinkCounter, ...]:
    """Every back-end's link-fault counters, in registry order."""
    return tuple(c for b in _BACKENDS for c in b.link_faults)


def link_stats() -> tuple[LinkStat, ...]:
    """Every back-end's link statistics, in registry order."""
    return tuple(c for b in _BACKENDS for c in b.link_stats)


def union(table: Literal["robot", "ft", "tracker"]) -> Any:
    """The discriminated union (on ``type``) of the config models of a rig table."""
    kinds: dict[str, Callable[[], Mapping[str, Any]]] = {
        "robot": _robots, "ft": _sensors, "tracker": _trackers}
    models = tuple(k.config for k in kinds[table]().values())
    if len(models) == 1:
        return models[0]
    # a Union built at run time from the registered models: pydantic reads it like a
    # written-out ``A | B | C`` with ``Field(discriminator="type")``
    return Annotated[_union_of(models), Field(discriminator="type")]


def _union_of(models: tuple[type[DeviceConfig], ...]) -> Any:
    from typing import Union

    return Union[models]  # noqa: UP007 (a tuple of types: no ``|`` spelling)


def backend_cdr_topics() -> tuple[CdrTopic, ...]:
    """The recording topics the back-ends define for their extras (CDR)."""
    from drivers.base.topics import CdrTopic

    return tuple(t for b in _BACKENDS for t in b.topics() if isinstance(t, CdrTopic))


def backend_json_topics() -> tuple[JsonTopic, ...]:
    """The recording topics the back-ends define for their extras (JSON)."""
    from drivers.base.topics import JsonTopic

    return tuple(t for b in _BACKENDS for t in b.topics() if isinstance(t, JsonTopic))


def _check_new(backend: Backend) -> None:
    taken = {e.name for e in emulators()}
    for emu in backend.emulators:
        if emu.name in taken:
            raise ValueError(f"back-end {backend.name!r}: emulator {emu.name!r} is taken")
    for kinds, have in ((backend.robots, _robots()), (backend.sensors, _sensors()),
                        (backend.trackers, _trackers())):
        for kind in kinds:
            if kind.rig_type in have:
                raise ValueError(f"back-end {backend.name!r}: type {kind.rig_type!r} is taken")
    drivers = driver_names()
    for robot in backend.robots:
        if robot.driver in drivers:
            raise ValueError(f"back-end {backend.name!r}: --driver {robot.driver!r} is taken")


def register(backend: Backend) -> None:
    """Add a back-end (its types must be new); the rig's unions include it from now on."""
    _check_new(backend)
    _BACKENDS.append(backend)
    _changed()


def unregister(backend: Backend) -> None:
    """Remove a back-end :func:`register` added."""
    _BACKENDS.remove(backend)
    _changed()


@contextmanager
def registered(backend: Backend) -> Iterator[Backend]:
    """:func:`register` for the duration of a ``with`` block (tests)."""
    register(backend)
    try:
        yield backend
    finally:
        unregister(backend)


def on_change(callback: Callable[[], None]) -> None:
    """Call ``callback()`` whenever :func:`register` or :func:`unregister` changed the registry."""
    _listeners.append(callback)


def _changed() -> None:
    for callback in _listeners:
        callback()
