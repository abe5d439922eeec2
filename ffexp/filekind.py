"""Which of ffexp's TOML files a table is: a run protocol, a campaign, a sweep protocol, an
impact protocol, a scene, a rig, a study: :func:`kind_of` and :func:`wrong_kind` are pure
(a parsed file in, a name out); :func:`load_as` and :func:`named_kind` read the file.

A file given where another kind is expected fails validation on its first
field (``name: unknown key`` for a protocol given as a rig); the error names the
fault instead: ``is a run protocol, not a rig``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, TypeVar

from pydantic import BaseModel

from drivers.config import load_model, read_toml
from drivers.errors import ConfigError

M = TypeVar("M", bound=BaseModel)

#: Tables (or keys) only one kind of file has, in the order they are tried.
_MARKS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("study", ("claims", "ranges", "grid", "include_nominal")),
    ("campaign", ("runs",)),
    ("impact protocol", ("impact", "faults")),
    ("sweep protocol", ("sweep", "model")),
    ("run protocol", ("align", "approach", "alignment", "estimation", "krc", "limits", "task")),
    ("rig", ("robot", "ft", "tracker")),
    ("scene", ("physics", "arm", "target", "contact", "ft_sensor", "tool", "base",
               "objects")),
)
#: How each kind is used on the command line.
USE = {
    "campaign": "ffexp campaign FILE",
    "sweep protocol": "ffexp simulate sweep FILE",
    "study": "ffexp reproduce --config FILE",  # protocols/reproduce.toml, robustness*.toml
    "run protocol": "ffexp run FILE",
    "impact protocol": "ffexp hil FILE",
    "rig": "--rig FILE",
    "scene": "a protocol's [scene] file, or --scene FILE",
}


def kind_of(data: Mapping[str, Any]) -> str | None:
    """The kind of ffexp file ``data`` looks like (``None``: none of them)."""
    runs = data.get("runs")
    if isinstance(runs, Mapping):  # a study's runs by role; a campaign's are a list
        return "study"
    for kind, marks in _MARKS:
        if kind == "run protocol" and "name" in data and "runs" not in data \
                and not any(k in data for k in ("sweep", "model")):
            if any(k in data for k in marks) or "scene" in data or "run" in data:
                return kind
        elif any(k in data for k in marks):
            return kind
    return None


def wrong_kind(data: Mapping[str, Any], expected: str) -> str | None:
    """``"is a run protocol, not a rig (use it as ffexp run FILE)"`` when ``data`` is
    recognisably another kind of file than ``expected``; ``None`` otherwise."""
    kind = kind_of(data)
    if kind is None or kind == expected:
        return None
    return f"is {_a(kind)}, not {_a(expected)} (use it as {USE[kind]})"


def _a(kind: str) -> str:
    return f"{'an' if kind[0] in 'aeiou' else 'a'} {kind}"


def named_kind(exc: ConfigError, path: Path, expected: str) -> ConfigError:
    """``exc``, or the error naming the fault when ``path`` is another kind of ffexp file
    than ``expected`` (a run protocol given as a rig)."""
    try:
        what = wrong_kind(read_toml(path), expected)
    except ConfigError:
        return exc
    return exc if what is None else ConfigError(str(path), "", what)


def load_as(model: type[M], path: Path, overrides: Iterable[str], expected: str) -> M:
    """``path`` validated as ``model`` (:func:`drivers.config.load_model`); when it fails
    and the file is another kind than ``expected``, the error says which and how it is
    used (``is a run protocol, not an impact protocol (use it as ffexp run FILE)``)."""
    try:
        return load_model(model, path, overrides)
    except ConfigError as exc:
        raise named_kind(exc, path, expected) from None
