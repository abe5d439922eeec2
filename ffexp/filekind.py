"""Which of ffexp's TOML files a table is: a run protocol, a campaign, a sweep protocol, an
impact protocol, a scene, a rig. Pure: a parsed file in, a name out.

A file given where another kind is expected fails validation on its first
field (``name: unknown key`` for a protocol given as a rig); the error names the
fault instead: ``is a run protocol, not a rig``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

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
    article = "an" if expected[0] in "aeiou" else "a"
    return f"is a {kind}, not {article} {expected} (use it as {USE[kind]})"
