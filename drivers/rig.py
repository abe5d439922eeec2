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

Devices have identities (LeRobot's ``id``): the robot and F/T sensor above are the
chaser, ``id = "chaser"`` unless the file says otherwise at its top. An optional
``[carrier]`` is a second robot with its own F/T sensor, the micro-gravity emulator
that carries the target's mock-up (``docs/hil.md``)::

    id = "chaser"
    [carrier]
    id = "carrier"
    [carrier.robot]
    type = "ur"
    robot_ip = "192.168.0.31"
    [carrier.ft]
    type = "netft"
    host = "192.168.1.2"

Two devices may not share an id, a carrier needs its own F/T sensor, and no
address (a host with a port) serves two devices, nor one controller address two
robots (loopback aside: emulators share it).

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
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

from pydantic import Field, model_validator
from pydantic.fields import FieldInfo

from drivers import registry
from drivers.base.backend import DeviceConfig
from drivers.config import StrictModel, apply_overrides, read_toml, validate
from drivers.errors import ConfigError

__all__ = ["CarrierDevice", "Rig", "default_rig", "load_rig", "validate_rig"]

_TABLES: tuple[typing.Literal["robot", "ft", "tracker"], ...] = ("robot", "ft", "tracker")

if TYPE_CHECKING:  # what code reads; the fields validate the registry's unions
    RobotConfig = DeviceConfig
    FtConfig = DeviceConfig
    TrackerConfig = DeviceConfig
else:
    RobotConfig = registry.union("robot")
    FtConfig = registry.union("ft")
    TrackerConfig = registry.union("tracker")

# A device's identity: its recording topics' prefix.
_DeviceId = Annotated[str, Field(pattern=r"^[a-z][a-z0-9_]{0,31}$")]
#: Fields of a device's table that hold a host, and those that hold a port.
_HOST_FIELDS = ("robot_ip", "host", "bind_host", "local_host")
_PORT_FIELDS = ("port", "robot_port", "rtde_port", "script_port", "local_port")
_LOOPBACK = ("127.", "localhost", "::1")


class CarrierDevice(StrictModel):
    """The second robot: the carrier that renders the target (``[carrier]``)."""

    id: _DeviceId = "carrier"
    robot: RobotConfig
    ft: FtConfig | None = None

    @model_validator(mode="after")
    def _pairs(self) -> CarrierDevice:
        if self.ft is None:
            raise ValueError("a carrier needs its own F/T sensor ([carrier.ft]): it renders "
                             "the target from the wrench that sensor measures")
        check = registry.ft_backend(self.ft.type).check(self.ft, self.robot)
        if check is not None:
            raise ValueError(check)
        return self


def _endpoints(table: str, cfg: DeviceConfig) -> Iterator[tuple[str, str, str]]:
    """``(host:port, host field, port field)`` of every host and port a table names."""
    for h in _HOST_FIELDS:
        host = getattr(cfg, h, None)
        if not isinstance(host, str) or not host:
            continue
        for p in _PORT_FIELDS:
            port = getattr(cfg, p, None)
            if isinstance(port, int) and port > 0:
                yield f"{host}:{port}", f"{table}.{h}", f"{table}.{p}"


class Rig(StrictModel):
    """A robot, an F/T sensor and (optionally) a target tracker and a carrier."""

    id: _DeviceId = "chaser"
    """The chaser's identity (its robot and F/T sensor)."""
    robot: RobotConfig = registry.robot_backend(registry.DEFAULT_ROBOT).config()
    ft: FtConfig = registry.ft_backend(
        registry.robot_backend(registry.DEFAULT_ROBOT).default_ft).config()
    tracker: TrackerConfig = registry.tracker_backend("none").config()
    carrier: CarrierDevice | None = None
    """The second robot, the micro-gravity emulator (``docs/hil.md``)."""

    @model_validator(mode="after")
    def _pairs(self) -> Rig:
        for check in (registry.ft_backend(self.ft.type).check(self.ft, self.robot),
                      registry.tracker_backend(self.tracker.type).check(self.tracker,
                                                                        self.robot)):
            if check is not None:
                raise ValueError(check)
        if self.carrier is not None:
            self._two_devices(self.carrier)
        return self

    def _two_devices(self, carrier: CarrierDevice) -> None:
        if carrier.id == self.id:
            raise ValueError(f"carrier.id '{carrier.id}' is the chaser's id too (the rig's "
                             "top-level id): two devices with one id")
        mine, theirs = (getattr(r, "robot_ip", None) for r in (self.robot, carrier.robot))
        if (isinstance(mine, str) and mine == theirs
                and not mine.startswith(_LOOPBACK)):
            raise ValueError(f"carrier.robot.robot_ip {theirs} is robot.robot_ip too: two "
                             "robots at one controller address")
        assert carrier.ft is not None
        seen: dict[str, str] = {}
        for table, cfg in (("robot", self.robot), ("ft", self.ft),
                           ("carrier.robot", carrier.robot), ("carrier.ft", carrier.ft)):
            for address, host, port in _endpoints(table, cfg):
                other = seen.get(address)
                if other is not None and (other.startswith("carrier.")
                                          != host.startswith("carrier.")):
                    raise ValueError(f"{host} and {port}: {address} is {other}'s address "
                                     "too: one address for two devices")
                seen.setdefault(address, host)


def _rebuild() -> None:
    """Rebuild the rig's unions after :func:`drivers.registry.register` changed them."""
    for table in _TABLES:
        old = Rig.__pydantic_fields__[table]
        Rig.__pydantic_fields__[table] = FieldInfo.from_annotated_attribute(
            registry.union(table), old.default)
    for table in ("robot", "ft"):
        old = CarrierDevice.__pydantic_fields__[table]
        union = registry.union(table)
        CarrierDevice.__pydantic_fields__[table] = FieldInfo.from_annotated_attribute(
            union if table == "robot" else union | None, old.default)
    CarrierDevice.model_rebuild(force=True)
    Rig.model_rebuild(force=True)


registry.on_change(_rebuild)


def _is_path(annotation: Any) -> bool:
    """``Path`` or ``Path | None``."""
    return annotation is Path or Path in typing.get_args(annotation)


def _relative_to(rig: Rig, folder: Path) -> Rig:
    """``rig`` with every relative ``Path`` field of its tables taken relative to ``folder``."""
    def relative(cfg: DeviceConfig) -> DeviceConfig:
        paths = {name: folder / value
                 for name, info in type(cfg).model_fields.items()
                 if _is_path(info.annotation)
                 and isinstance(value := getattr(cfg, name), Path) and not value.is_absolute()}
        return cfg.model_copy(update=paths) if paths else cfg

    update: dict[str, Any] = {table: relative(getattr(rig, table)) for table in _TABLES}
    if rig.carrier is not None:
        update["carrier"] = rig.carrier.model_copy(update={
            t: relative(c) for t in ("robot", "ft")
            if (c := getattr(rig.carrier, t)) is not None})
    return rig.model_copy(update=update)


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
        at = 1 if parts[0] == "carrier" else 0  # [carrier.robot], [carrier.ft]
        if (len(parts) >= at + 3 and parts[at] in tags
                and parts[at + 1] in tags[parts[at]]()):
            del parts[at + 1]
            raise ConfigError(source, ".".join(parts), exc.message) from None
        raise


def default_rig() -> Rig:
    """The built-in rig: the simulated robot and its simulated sensor."""
    return Rig()
