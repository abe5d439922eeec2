"""The rig of a study (``--rig``, ``--driver``, ``--rig-set``): checked, named, hashed into
the run ids and copied for the workers.

A study's runs go to parallel workers (a process pool, batches, Ray), so only a rig
whose devices all live in the worker's own process may run one:

- its robot is simulated in-process: its back-end states its scene before it opens
  (:attr:`drivers.base.backend.RobotBackend.scene`; ``None`` is the registry's word for
  a real robot or one behind a link: ``fri1``, ``ur``, ``franka``, an emulator's rig);
- its F/T sensor and tracker are read from that robot: each says it goes only with
  certain robots (its ``check`` refuses a robot that offers nothing: the world's sensor
  and camera model, a robot's own wrench estimate), or there is no tracker. A device that
  goes with any robot is one of its own (a Net F/T box, a camera, a script);
- it has no carrier (``ffexp hil`` runs one).

Anything else is refused before any run: one line naming the rig and the field.

:class:`StudyRig` is a checked rig; :func:`study_rig` makes one of a command line's
:class:`~ffexp.rig_choice.RigChoice` (``None`` for the built-in rig as it is, whose runs
keep the ids they had before studies took a rig).
"""

from __future__ import annotations

import hashlib
import json
import typing
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from drivers import registry
from drivers.base.backend import DeviceConfig, OpenContext
from ffexp.errors import ConfigError
from ffexp.rig_choice import DEFAULT_DRIVER, RigChoice
from ffexp.sweeps.keys import toml_text

if TYPE_CHECKING:
    from drivers.description.scene import Scene
    from drivers.rig import Rig

#: The ``rig`` column of a run on the built-in rig (as a run's metadata names it).
BUILTIN = f"<built-in {DEFAULT_DRIVER} rig>"
#: The rig file's name in a target's inputs folder (``DIR/inputs/<target>/``).
RIG_FILE = "rig.toml"
_TABLES = ("robot", "ft", "tracker")


def simulated_robots() -> list[str]:
    """The ``[robot] type`` names the registry says are simulated in-process."""
    return [t for t in registry.robot_types() if registry.robot_backend(t).scene is not None]


def simulated_drivers() -> list[str]:
    """The ``--driver`` names of the simulated robots."""
    return [registry.robot_backend(t).driver for t in simulated_robots()]


def _paths(model: Rig) -> Iterator[tuple[str, str, Path]]:
    """``(table, field, path)`` of every file a rig's tables name (resolved paths)."""
    for table in _TABLES:
        cfg = getattr(model, table)
        for name, info in type(cfg).model_fields.items():
            value = getattr(cfg, name)
            if isinstance(value, Path) and (info.annotation is Path
                                            or Path in typing.get_args(info.annotation)):
                yield table, name, value


_WHY = "a study's runs go to parallel workers, which cannot share one robot or device"


def _check_robot(robot_type: str, source: str) -> None:
    """Refuse a robot type the registry does not say is simulated in-process."""
    if registry.robot_backend(robot_type).scene is not None:
        return
    sims = ", ".join(f"{t!r} (--driver {d})"
                     for t, d in zip(simulated_robots(), simulated_drivers(), strict=True))
    raise ConfigError(source, "robot.type", f"{robot_type!r} is not simulated in this "
                      f"process ({_WHY}); use a simulated robot: {sims}")


def _robot_type(choice: RigChoice) -> tuple[str | None, str]:
    """The robot type a rig choice names, read before the rig is validated (so that a lab
    rig is refused for what it is, not for a field it lacks), and the rig's name."""
    from drivers.config import apply_overrides, read_toml

    if choice.path is None:
        driver = choice.driver or DEFAULT_DRIVER
        robot = registry.robot_for_driver(driver)
        return (None if robot is None else robot.rig_type), f"<built-in {driver} rig>"
    try:
        data = apply_overrides(read_toml(choice.path), choice.overrides)
    except ConfigError:
        return None, str(choice.path)  # the rig's own loading names the fault
    table = data.get("robot")
    kind = table.get("type") if isinstance(table, dict) else None
    return (kind if kind in registry.robot_types() else None), str(choice.path)


def check_study_rig(model: Rig, source: str) -> None:
    """Refuse a rig whose devices are not all simulated in the worker's process (one-line
    :class:`~ffexp.errors.ConfigError` naming ``source`` and the field; see the module)."""
    if model.carrier is not None:
        raise ConfigError(source, "carrier", f"a study runs no carrier ({_WHY}; the carrier "
                          "runs in ffexp hil)")
    _check_robot(model.robot.type, source)
    bare = DeviceConfig.model_construct(type="")  # a robot that offers nothing
    for table, backend in (("ft", registry.ft_backend(model.ft.type)),
                           ("tracker", registry.tracker_backend(model.tracker.type))):
        cfg = getattr(model, table)
        if table == "tracker" and cfg.type == "none":
            continue
        if backend.check(cfg, bare) is None:  # it goes with any robot: a device of its own
            raise ConfigError(source, f"{table}.type", f"{cfg.type!r} is a device of its own, "
                              f"not the simulated robot's ({_WHY}); use "
                              "the simulator's (the robot's default)")


@dataclass(frozen=True)
class StudyRig:
    """A rig a study may run on (:func:`check_study_rig` passed), as the runs use it."""

    choice: RigChoice
    model: Rig
    name: str
    """The rig file as given, or ``<built-in DRIVER rig>``: the rows' ``rig``."""

    def identity(self) -> str:
        """The rig's resolved content as text (each file a table names by its bytes'
        digest, not its path: a copy of the same rig is the same rig)."""
        data = self.model.model_dump(mode="json")
        for table, name, path in _paths(self.model):
            data[table][name] = "sha1:" + _digest(path, self.name, f"{table}.{name}")
        return json.dumps(data, sort_keys=True)

    def scene(self, scene_file: Path, overrides: Sequence[str], seed: int = 0) -> Scene:
        """The scene the rig's robot runs in, given the protocol's scene file and overrides
        (the robot's own file if its table names one; its arm swapped in if it does so)."""
        state = registry.robot_backend(self.model.robot.type).scene
        assert state is not None  # checked: a simulated robot
        return state(self.model.robot, OpenContext(self.name, scene_file, tuple(overrides),
                                                   seed))

    def job_rig(self, folder: Path) -> tuple[str | None, tuple[str, ...], str | None]:
        """``(rig file, overrides, driver)`` of a job whose inputs are in ``folder`` (what
        :meth:`copy_into` wrote there): the copied files named by absolute paths."""
        moved = tuple(f"{table}.{name}={toml_text(str(folder / _copy_name(table, name, p)))}"
                      for table, name, p in _paths(self.model))
        overrides = (*self.choice.overrides, *moved)
        if self.choice.path is None:
            return None, overrides, self.choice.driver or DEFAULT_DRIVER
        return str(folder / RIG_FILE), overrides, None

    def copy_into(self, folder: Path) -> None:
        """Copy the rig file and the files its tables name into ``folder`` (what the
        workers read, on any node that sees the study's directory)."""
        files = [(RIG_FILE, self.choice.path, "")] if self.choice.path is not None else []
        files += [(_copy_name(t, n, p), p, f"{t}.{n}") for t, n, p in _paths(self.model)]
        for name, src, where in files:
            assert src is not None
            try:
                data = src.read_bytes()
            except OSError as exc:
                raise ConfigError(self.name, where, f"{src}: {exc.strerror}") from None
            dst = folder / name
            if not dst.exists() or dst.read_bytes() != data:
                tmp = folder / f".{name}.tmp"
                tmp.write_bytes(data)
                tmp.replace(dst)


def _copy_name(table: str, name: str, path: Path) -> str:
    return f"rig-{table}-{name}{path.suffix}"


def _digest(path: Path, source: str, where: str) -> str:
    try:
        return hashlib.sha1(path.read_bytes(), usedforsecurity=False).hexdigest()
    except OSError as exc:
        raise ConfigError(source, where, f"{path}: {exc.strerror}") from None


def is_builtin(choice: RigChoice) -> bool:
    """The built-in rig as it is (no file, no override, the default driver)."""
    return (choice.path is None and not choice.overrides
            and (choice.driver or DEFAULT_DRIVER) == DEFAULT_DRIVER)


def study_rig(choice: RigChoice) -> StudyRig | None:
    """The checked rig of a study (``None``: the built-in rig as it is)."""
    if is_builtin(choice):
        return None
    from ffexp.experiment import load_rig_choice

    kind, name = _robot_type(choice)
    if kind is not None:
        _check_robot(kind, name)
    model, name = load_rig_choice(choice)
    check_study_rig(model, name)
    for table, field, path in _paths(model):
        if not path.is_file():
            raise ConfigError(name, f"{table}.{field}", f"{path}: file not found")
    return StudyRig(choice, model, name)

