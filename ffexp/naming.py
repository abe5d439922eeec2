"""Names of runs, figures and reports: readable, unique, never overwriting.

A run is named ``<protocol>-<robot>-<overrides id>-<UTC time>``, e.g.
``method2-sim-a41c09-20261123-190102`` (the robot: the rig's ``robot.type``,
so a run on the UR says so: ``method2-ur-...``): the overrides id is ``base`` without
overrides, else the first 6 hex digits of a hash of the overrides in the
order given, so that runs of one protocol with different ``--set`` values
(a campaign over three f_ref values) differ by name even within one second.
A name that is taken gets ``-1``, ``-2``, ...; :func:`reserve` creates the
file exclusively, so two processes never get the same one.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from datetime import datetime
from pathlib import Path

BASE_ID = "base"
STAMP_FORMAT = "%Y%m%d-%H%M%S"


def overrides_id(overrides: Sequence[str]) -> str:
    """``base`` for no overrides, else 6 hex digits that identify them."""
    if not overrides:
        return BASE_ID
    digest = hashlib.sha1(json.dumps(list(overrides)).encode(), usedforsecurity=False)
    return digest.hexdigest()[:6]


def stamp(when: datetime) -> str:
    """``20261123-190102`` (sorts by time)."""
    return when.strftime(STAMP_FORMAT)


def run_stem(protocol: str, overrides: Sequence[str], when: datetime, robot: str = "") -> str:
    """``<protocol>-<robot>-<overrides id>-<time>`` (without ``robot``: no robot part)."""
    who = f"{robot}-" if robot else ""
    return f"{protocol}-{who}{overrides_id(overrides)}-{stamp(when)}"


def unique_stem(out_dir: Path, stem: str, suffixes: Sequence[str]) -> str:
    """``stem``, or ``stem-1``, ``stem-2``, ...: the first with no file of any suffix."""
    k = 0
    candidate = stem
    while any((out_dir / f"{candidate}{sfx}").exists() for sfx in suffixes):
        k += 1
        candidate = f"{stem}-{k}"
    return candidate


def reserve(out_dir: Path, stem: str, suffix: str) -> Path:
    """Create ``out_dir/<stem><suffix>`` (or the first free ``-k`` variant) exclusively.

    The empty file is the caller's to overwrite; another process asking for
    the same name gets the next one.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    k = 0
    while True:
        name = stem if k == 0 else f"{stem}-{k}"
        path = out_dir / f"{name}{suffix}"
        try:
            path.open("x").close()
        except FileExistsError:
            k += 1
            continue
        return path
