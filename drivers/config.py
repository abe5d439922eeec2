"""Loading TOML files into pydantic models, with one-line errors.

Every protocol and scene in ffexp goes through :func:`load_model`: the file is
parsed with :mod:`tomllib`, ``--set dotted.key=value`` overrides are applied,
and the result is validated by a pydantic model that rejects unknown keys.
Any problem becomes a :class:`~drivers.errors.ConfigError` that names the file
and the field, e.g. ``sec3.toml: sweep.values: Input should be a valid list``.

Every number of every model is finite (``nan``, ``inf`` and a literal that
overflows to ``inf``, such as ``1e400``, are errors), and every time is in
range: a field in seconds (``*_s``), milliseconds (``*_ms``) or a rate
(``*_hz``, its period) at most :data:`MAX_TIME_S` seconds, so that every time
is an int64 number of nanoseconds from the run's start.

The project's type aliases for numbers and vectors are declared here, once (light:
pydantic only), in two kinds:

* fixed-length tuples, a static type (``Vec3``, ``Vec6``, ``Bool6``): code and models
  that take exactly three or six values;
* validated fields of a config model (``PosFloat``, ``NonNeg``, ``Port``, and
  ``Floats2``/``Floats3``/``Floats6``/``PerJoint``, a ``tuple[float, ...]`` whose length
  pydantic checks: the scene's vectors).

The array alias ``F64`` (a float64 numpy array) is :mod:`drivers.base.types`'.
"""

from __future__ import annotations

import stat
import tomllib
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Annotated, Any, TypeVar

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    ValidationInfo,
    field_validator,
)

from drivers.errors import ConfigError

M = TypeVar("M", bound=BaseModel)

#: Three floats (a point, an axis, a size) [its unit in the name that holds it].
Vec3 = tuple[float, float, float]
#: Six floats: per TCF axis ``[x, y, z, rx, ry, rz]``, or a wrench or twist.
Vec6 = tuple[float, float, float, float, float, float]
#: Six flags, per TCF axis.
Bool6 = tuple[bool, bool, bool, bool, bool, bool]

#: A float above zero.
PosFloat = Annotated[float, Field(gt=0.0)]
#: A float of zero or more.
NonNeg = Annotated[float, Field(ge=0.0)]
#: A UDP or TCP port number (0: any free one, where a field allows it).
Port = Annotated[int, Field(ge=0, le=65535)]
#: Two floats (a force's and a torque's value), length checked.
Floats2 = Annotated[tuple[float, ...], Field(min_length=2, max_length=2)]
#: Three floats, length checked.
Floats3 = Annotated[tuple[float, ...], Field(min_length=3, max_length=3)]
#: Six floats, length checked.
Floats6 = Annotated[tuple[float, ...], Field(min_length=6, max_length=6)]
#: One float per joint, for arms of up to seven joints (its model says how many).
PerJoint = Annotated[tuple[float, ...], Field(min_length=1, max_length=7)]


#: The longest time any configuration may give (about 11.6 days) [s].
MAX_TIME_S = 1e6
#: Per unit suffix of a field's name: the factor from the field's value to seconds.
_TIME_UNITS: tuple[tuple[str, float], ...] = (("_ms", 1e-3), ("_s", 1.0))


def _numbers(value: Any) -> Iterable[float]:
    """The plain numbers in a field's value (itself, or a list's or tuple's items)."""
    if isinstance(value, bool):
        return ()
    if isinstance(value, int | float):
        return (float(value),)
    if isinstance(value, list | tuple):
        return [float(v) for v in value if isinstance(v, int | float) and not isinstance(v, bool)]
    return ()


class StrictModel(BaseModel):
    """Base of every configuration model: unknown keys are errors, fields frozen, every
    number finite and every time (``*_s``, ``*_ms``, the period of ``*_hz``) in range."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    @field_validator("*", mode="after")
    @classmethod
    def _time_in_range(cls, value: Any, info: ValidationInfo) -> Any:
        name = info.field_name or ""
        for x in _numbers(value):
            if name.endswith("_hz"):
                if x != 0.0 and not abs(1.0 / x) <= MAX_TIME_S:
                    raise ValueError(f"a rate below {1.0 / MAX_TIME_S:g} Hz (a period over "
                                     f"{MAX_TIME_S:g} s) is out of range")
                continue
            for suffix, to_s in _TIME_UNITS:
                if name.endswith(suffix) and not abs(x * to_s) <= MAX_TIME_S:
                    raise ValueError(f"must be at most {MAX_TIME_S / to_s:g} "
                                     f"{suffix.removeprefix('_')} in magnitude")
        return value


def parse_override(text: str) -> tuple[list[str], Any]:
    """Split ``a.b.c=value`` into its key path and a TOML-typed value.

    The value is read as a TOML value (``1``, ``0.5``, ``true``, ``[1, 2]``,
    ``"text"``); anything that is not valid TOML is taken as a plain string.

    Raises:
        ConfigError: the text has no ``=`` or an empty key.
    """
    key, sep, raw = text.partition("=")
    key = key.strip()
    if not sep or not key or any(not part for part in key.split(".")):
        raise ConfigError("--set", text, "expected dotted.key=value")
    raw = raw.strip()
    try:
        value: Any = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw
    return key.split("."), value


def apply_overrides(data: dict[str, Any], overrides: Iterable[str]) -> dict[str, Any]:
    """Return a copy of ``data`` with every ``dotted.key=value`` override applied."""
    result = _deep_copy(data)
    for text in overrides:
        path, value = parse_override(text)
        node = result
        for part in path[:-1]:
            child = node.get(part)
            if child is None:
                child = {}
                node[part] = child
            elif not isinstance(child, dict):
                raise ConfigError("--set", text, f"'{part}' is not a table")
            node = child
        node[path[-1]] = value
    return result


def _deep_copy(data: Mapping[str, Any]) -> dict[str, Any]:
    return {k: _deep_copy(v) if isinstance(v, Mapping) else v for k, v in data.items()}


def not_regular(path: Path) -> str:
    """What ``path`` is when it exists but is neither a regular file nor a directory (a
    FIFO, a device, a socket), which reading would block on or never end; else ``""``."""
    try:
        mode = path.stat().st_mode
    except OSError:
        return ""
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return ""
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    return "a socket" if stat.S_ISSOCK(mode) else "a special file"


def read_toml(path: Path) -> dict[str, Any]:
    """Parse a TOML file; a missing or malformed file is a :class:`ConfigError`."""
    odd = not_regular(path)
    if odd:
        raise ConfigError(str(path), "", f"is {odd}, not a regular TOML file")
    try:
        with path.open("rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ConfigError(str(path), "", "file not found") from None
    except IsADirectoryError:
        raise ConfigError(str(path), "", "is a directory, expected a TOML file") from None
    except PermissionError:
        raise ConfigError(str(path), "", "permission denied") from None
    except UnicodeDecodeError:
        raise ConfigError(str(path), "", "not a text file") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(str(path), "", f"invalid TOML: {exc}") from None


def validate(model: type[M], data: Mapping[str, Any], source: str) -> M:
    """Validate ``data`` against ``model``; the first error becomes a ConfigError."""
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        field = ".".join(str(p) for p in err["loc"])
        message = err["msg"]
        if err["type"] == "value_error" and "error" in err.get("ctx", {}):
            message = str(err["ctx"]["error"])
        if err["type"] == "extra_forbidden":
            message = "unknown key"
        more = exc.error_count() - 1
        if more:
            message += f" (and {more} more error{'s' if more > 1 else ''})"
        raise ConfigError(source, field, message) from None


def load_model(model: type[M], path: Path, overrides: Iterable[str] = ()) -> M:
    """Read ``path`` as TOML, apply overrides, validate as ``model``."""
    data = apply_overrides(read_toml(path), overrides)
    return validate(model, data, str(path))
