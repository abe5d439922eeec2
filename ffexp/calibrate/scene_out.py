"""The calibrated scene as a TOML file, with its provenance in comments.

The whole scene is written (every key, the fitted ones replaced), so the file
stands alone: ``[scene] file = ...`` in a protocol or ``robot.scene_file`` in a
rig takes it as it is. The scene model accepts no unknown keys, so the
provenance (recordings, source revision, residuals, each value's interval) is
in comments: a header block and one comment beside each fitted key.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ffexp.sweeps.keys import toml_text


def _table(lines: list[str], name: str, data: Mapping[str, Any],
           notes: Mapping[str, str]) -> None:
    scalars = {k: v for k, v in data.items() if not isinstance(v, Mapping) and v is not None}
    tables = {k: v for k, v in data.items() if isinstance(v, Mapping)}
    if name and scalars:
        lines.append("")
        lines.append(f"[{name}]")
    for key, value in scalars.items():
        full = f"{name}.{key}" if name else key
        note = notes.get(full)
        lines.append(f"{key} = {toml_text(value)}" + (f"   # {note}" if note else ""))
    for key, sub in tables.items():
        _table(lines, f"{name}.{key}" if name else key, sub, notes)


def scene_text(scene: Mapping[str, Any], header: Sequence[str],
               notes: Mapping[str, str]) -> str:
    """``scene`` (JSON data of a whole scene) as TOML, ``header`` lines as comments first."""
    lines = [f"# {h}" if h else "#" for h in header]
    _table(lines, "", scene, notes)
    return "\n".join(lines) + "\n"


def set_key(scene: dict[str, Any], key: str, value: Any) -> None:
    """Set the dotted ``key`` of nested ``scene`` in place."""
    node = scene
    *path, last = key.split(".")
    for part in path:
        node = node[part]
    node[last] = value


def write_scene(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file (never a half-written scene)."""
    tmp = path.with_name(path.name + ".part")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(path)
