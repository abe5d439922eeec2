"""Rig files (``rigs/*.toml``): which robot, F/T and tracker back-ends a run uses, and every
hardware number.

A rig has two tables, each discriminated by ``type``::

    [robot]
    type = "fri1"            # "sim" | "fri1" | "mock"
    robot_ip = "192.168.0.20"
    port = 49938

    [ft]
    type = "netft"           # "sim" | "netft" | "fri-estimate" | "mock"
    host = "192.168.1.1"

An optional third table names the target tracker (default ``"none"``)::

    [tracker]
    type = "camera"          # "none" | "sim" | "camera"
    source = "http://127.0.0.1:8080/stream.mjpg"   # device index, file or URL
    calibration = "camera-calibration.toml"

The types and their tables are the back-ends' config models, taken from
:mod:`drivers.registry` (each back-end folder defines its own). Addresses,
ports, counts per unit, timeouts, the answer deadline and the cycle limits live
here; command-line flags only override these fields (``robot.port=49939``).
Errors name the file and the field (``rigs/lwr4-lab.toml: robot.port: ...``). A
``Path`` field is relative to the rig file. Cross-checks (each F/T source and
tracker says which robots it goes with): the simulated sensor only with the
simulated robot; the F/T estimate only with an FRI robot.

Pure configuration: building devices from a rig is :mod:`drivers.factory`.
"""

from __future__ import annotations

import typing
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pydantic import model_validator
from pydantic.fields import FieldInfo

from drivers import registry
from drivers.base.backend import DeviceConfig
from drivers.config import StrictModel, apply_overrides, read_toml, validate
from drivers.errors import ConfigError

__all__ = ["Rig", "default_rig", "load_rig", "validate_rig"]

_TABLES: tuple[typing.Literal["robot", "ft", "tracker"], ...] = ("robot", "ft", "tracker")

if TYPE_CHECKING:  # what code reads; the fields validate the registry's unions
    RobotConfig = DeviceConfig
    FtConfig = DeviceConfig
    TrackerConfig = DeviceConfig
else:
    RobotConfig = registry.union("robot")
    FtConfig = registry.union("ft")
    TrackerConfig = registry.union("tracker")

class Rig(StrictModel):
    """A robot, an F/T sensor and (optionally) a target tracker."""

    robot: RobotConfig = registry.robot_backend(registry.DEFAULT_ROBOT).config()
    ft: FtConfig = registry.ft_backend(
        registry.robot_backend(registry.DEFAULT_ROBOT).default_ft).config()
    tracker: TrackerConfig = registry.tracker_backend("none").config()

    @model_validator(mode="after")
    def _pairs(self) -> Rig:
        for check in (registry.ft_backend(self.ft.type).check(self.ft, self.robot),
                      registry.tracker_backend(self.tracker.type).check(self.tracker,
                                                                        self.robot)):
            if check is not None:
                raise ValueError(check)
        return self


def _rebuild() -> None:
    """Rebuild the rig's unions after :func:`drivers.registry.register` changed them."""
    for table in _TABLES:
        old = Rig.__pydantic_fields__[table]
        Rig.__pydantic_fields__[table] = FieldInfo.from_annotated_attribute(
            registry.union(table), old.default)
    Rig.model_rebuild(force=True)


registry.on_change(_rebuild)


def _is_path(annotation: Any) -> bool:
    """``Path`` or ``Path | None``."""
    return annotation is Path or Path in typing.get_args(annotation)


def _relative_to(rig: Rig, folder: Path) -> Rig:
    """``rig`` with every relative ``Path`` field of its tables taken relative to ``folder``."""
    update: dict[str, DeviceConfig] = {}
    for table in _TABLES:
        cfg: DeviceConfig = getattr(rig, table)
        paths = {name: folder / value
                 for name, info in type(cfg).model_fields.items()
                 if _is_path(info.annotation)
                 and isinstance(value := getattr(cfg, name), Path) and not value.is_absolute()}
        if paths:
            update[table] = cfg.model_copy(update=paths)
    return rig.model_copy(update=update) if update else rig


def load_rig(path: Path, overrides: Iterable[str] = ()) -> Rig:
    """Read a rig file, apply ``dotted.key=value`` overrides, validate.

    A relative path in a table (``robot.scene_file``, ``tracker.calibration``) is
    taken relative to the rig file.

    Raises:
        ConfigError: ``"<path>: <field>: <message>"``.
    """
    raw = read_toml(path)
    if not raw:  # an empty file is not a rig (it would silently be the built-in sim rig)
        robots = " | ".join(f'"{t}"' for t in registry.robot_types())
        raise ConfigError(str(path), "", "empty rig file: a rig names its devices, "
                          f"[robot] type = {robots} and [ft] type = ...")
    data = apply_overrides(raw, overrides)
    return _relative_to(validate_rig(data, str(path)), path.parent)


def validate_rig(data: Mapping[str, Any], source: str) -> Rig:
    """Validate rig data; errors name ``robot.port``, not pydantic's ``robot.fri1.port``."""
    try:
        return validate(Rig, data, source)
    except ConfigError as exc:
        parts = exc.field.split(".")
        tags = {"robot": registry.robot_types, "ft": registry.ft_types,
                "tracker": registry.tracker_types}
        if len(parts) >= 3 and parts[0] in tags and parts[1] in tags[parts[0]]():
            del parts[1]
            raise ConfigError(source, ".".join(parts), exc.message) from None
        raise


def default_rig() -> Rig:
    """The built-in rig: the simulated robot and its simulated sensor."""
    return Rig()
