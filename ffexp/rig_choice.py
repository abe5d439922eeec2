"""Which rig a run uses, as the command line says it (light: imports nothing heavy).

:mod:`ffexp.experiment` loads the rig; the CLI only builds a :class:`RigChoice`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

#: ``--driver`` shortcuts: the robot back-end of the rig when no ``--rig`` is given.
DRIVERS = ("sim", "fri", "mock")
#: ``--ft`` values: the F/T back-end of the rig.
FT_SOURCES = ("sim", "netft", "fri-estimate", "mock")


@dataclass(frozen=True)
class RigChoice:
    """Which rig a run uses: a rig file (or the built-in sim rig) and field overrides.

    ``overrides`` are ``dotted.key=value`` strings on the rig's fields, e.g.
    ``robot.robot_ip=192.168.0.10``; the CLI turns its device flags into these.
    """

    path: Path | None = None
    overrides: tuple[str, ...] = ()
    driver: str | None = None
    """With no ``path``: the robot back-end of the built-in rig (``sim``, ``fri``, ``mock``)."""
