"""The target tracker: camera calibration and checks.

Light at module level (typer and the standard library only); each command
imports what it needs inside. ``COMMANDS`` lists ``(name, function)`` pairs
that :mod:`ffexp.cli` mounts as top-level commands.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

COMMANDS: list[tuple[str, Callable[..., Any]]] = []
