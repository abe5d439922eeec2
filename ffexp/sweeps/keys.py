"""Sweep keys and values: parsing, canonical text, and the ``--set`` overrides of a point.

A sweep key is any protocol key (``align.f_ref``, ``approach.speed_mps``), a
scene key (``scene.target.lateral``: it becomes an entry of the protocol's
``[scene] set = [...]``), or either with an index into a list
(``align.k_ri[3]`` replaces one element of the protocol's list). Values are
TOML values (``0.5``, ``true``, ``[0, 0, 1]``, ``"text"``). Pure: no I/O.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
import tomllib
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from ffexp.errors import ConfigError

#: Protocol keys under ``scene`` that belong to the protocol itself, not to the scene.
PROTOCOL_SCENE_FIELDS = ("file", "set")
_KEY = re.compile(r"^(?P<path>[A-Za-z_][A-Za-z0-9_]*(?:\.[A-Za-z_][A-Za-z0-9_]*)*)"
                  r"(?:\[(?P<index>\d+)\])?$")

Value = bool | int | float | str | list[Any]


@dataclass(frozen=True)
class Key:
    """One sweep key as written (``scene.target.lateral``, ``align.k_ri[3]``)."""

    text: str
    path: tuple[str, ...]
    """Dotted path inside its model (the scene's for a scene key, without ``scene.``)."""
    index: int | None
    scene: bool

    @property
    def dotted(self) -> str:
        """The dotted path as an override names it (``target.lateral``, ``align.k_ri``)."""
        return ".".join(self.path)


def parse_key(text: str, option: str = "--vary") -> Key:
    """``align.k_ri[3]`` -> Key; a malformed key is a ConfigError naming ``option``."""
    m = _KEY.match(text.strip())
    if m is None:
        raise ConfigError(option, text, "expected a dotted key, e.g. align.kp or align.k_ri[3]")
    parts = tuple(m["path"].split("."))
    index = int(m["index"]) if m["index"] is not None else None
    if parts[0] == "scene" and len(parts) > 1 and parts[1] not in PROTOCOL_SCENE_FIELDS:
        return Key(m.group(0), parts[1:], index, scene=True)
    if parts == ("seed",):
        raise ConfigError(option, text, "the seed is not a sweep key; use --seeds N")
    return Key(m.group(0), parts, index, scene=False)


def parse_values(text: str, option: str = "--vary") -> list[Value]:
    """``0.5,1,2`` (or ``[0,0,1],[0,0,2]``) -> a list of TOML values; bare words are
    strings (``impedance,force``). An empty list is a ConfigError."""
    raw = text.strip()
    try:
        values: list[Value] = tomllib.loads(f"v = [{raw}]")["v"]
    except tomllib.TOMLDecodeError:
        values = [v.strip() for v in raw.split(",")]
    if not values or any(v == "" for v in values):
        raise ConfigError(option, text, "no values (expected V1,V2,...)")
    return _floats_if_any(values)


def parse_assignment(text: str, option: str = "--vary") -> tuple[Key, list[Value]]:
    """``KEY=V1,V2,...`` -> (key, values)."""
    key, sep, raw = text.partition("=")
    if not sep:
        raise ConfigError(option, text, "expected KEY=V1,V2,...")
    return parse_key(key, option), parse_values(raw, option)


def parse_range(text: str, option: str = "--range") -> tuple[Key | None, float, float]:
    """``KEY=LO:HI`` (or ``LO:HI``) -> (key or None, lo, hi) with finite lo < hi."""
    key: Key | None = None
    raw = text
    if "=" in text:
        k, _, raw = text.partition("=")
        key = parse_key(k, option)
    lo_s, sep, hi_s = raw.partition(":")
    try:
        lo, hi = float(lo_s), float(hi_s)
    except ValueError:
        lo = hi = math.nan
    if not sep or not (math.isfinite(lo) and math.isfinite(hi)):
        raise ConfigError(option, text, "expected LO:HI with two numbers")
    if not lo < hi:
        raise ConfigError(option, text, "empty range: LO must be below HI")
    return key, lo, hi


def _floats_if_any(values: list[Value]) -> list[Value]:
    """Integers become floats when any value is a float (``0,0.5,1``: one type, one id)."""
    numbers = [v for v in values if isinstance(v, int | float) and not isinstance(v, bool)]
    if numbers and any(isinstance(v, float) for v in numbers):
        return [float(v) if v in numbers else v for v in values]
    return values


def toml_text(value: Value | tuple[Any, ...]) -> str:
    """A value as TOML text, canonical (floats by ``repr``, strings JSON-quoted, a list or
    tuple as an array): what ``--set`` parses, and what a written scene holds."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"not a finite number: {value}")
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list | tuple):
        return "[" + ", ".join(toml_text(v) for v in value) + "]"
    raise TypeError(f"cannot write {type(value).__name__} as TOML")


def canonical(point: Mapping[str, Value], seed: int) -> str:
    """The point's canonical text: keys sorted, values as TOML, then the seed."""
    items = [f"{k}={toml_text(point[k])}" for k in sorted(point)]
    return json.dumps({"set": items, "seed": seed}, sort_keys=True)


def run_id(protocol_id: str, point: Mapping[str, Value], seed: int, fixed: Sequence[str]) -> str:
    """12 hex digits from the protocol (its name and resolved content), the fixed
    ``--set`` overrides, the point's canonical overrides and the seed."""
    text = json.dumps([protocol_id, list(fixed), canonical(point, seed)])
    return hashlib.sha1(text.encode(), usedforsecurity=False).hexdigest()[:12]


def point_overrides(
    keys: Iterable[Key],
    point: Mapping[str, Value],
    base_protocol: Mapping[str, Any],
    base_scene: Mapping[str, Any],
    scene_set: Sequence[str],
) -> list[str]:
    """The ``--set`` overrides that put ``point`` into the protocol.

    ``base_protocol`` and ``base_scene`` are the resolved models (as dicts) the
    index keys take their lists from; ``scene_set`` is the protocol's own
    ``[scene] set``, which the scene keys extend.

    Raises:
        ConfigError: an index key names a field that is not a list, or an
            index past its end.
    """
    lists: dict[tuple[bool, str], list[Any]] = {}
    protocol_sets: list[str] = []
    scene_sets: list[str] = []
    for key in keys:
        value = point[key.text]
        if key.index is not None:
            ident = (key.scene, key.dotted)
            if ident not in lists:
                lists[ident] = list(_lookup(base_scene if key.scene else base_protocol, key))
            current = lists[ident]
            if key.index >= len(current):
                raise ConfigError("--vary", key.text,
                                  f"index {key.index} past the end of a list of {len(current)}")
            current[key.index] = value
            continue
        text = f"{key.dotted}={toml_text(value)}"
        (scene_sets if key.scene else protocol_sets).append(text)
    for (is_scene, dotted), values in lists.items():
        text = f"{dotted}={toml_text(values)}"
        (scene_sets if is_scene else protocol_sets).append(text)
    if scene_sets:
        protocol_sets.append("scene.set=" + toml_text([*scene_set, *scene_sets]))
    return protocol_sets


def _lookup(tree: Mapping[str, Any], key: Key) -> list[Any]:
    node = _walk(tree, key)
    if not isinstance(node, list | tuple):
        raise ConfigError("--vary", key.text, f"{key.dotted} is not a list; drop the index")
    return list(node)


def _walk(tree: Mapping[str, Any], key: Key) -> Any:
    node: Any = tree
    for part in key.path:
        if not isinstance(node, Mapping) or part not in node:
            where = "scene" if key.scene else "protocol"
            raise ConfigError("--vary", key.text, f"unknown key (no {key.dotted} in the {where})")
        node = node[part]
    return node


def current_value(key: Key, protocol: Mapping[str, Any], scene: Mapping[str, Any]) -> Any:
    """The value a key has in the resolved protocol and scene (as dicts): the nominal
    value that relative sweep values (offsets, scales) start from."""
    if key.index is None:
        return _walk(scene if key.scene else protocol, key)
    values = _lookup(scene if key.scene else protocol, key)
    if key.index >= len(values):
        raise ConfigError("--vary", key.text,
                          f"index {key.index} past the end of a list of {len(values)}")
    return values[key.index]
