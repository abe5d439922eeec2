"""Which rig a run uses, as the command line says it (light: imports nothing heavy).

:mod:`ffexp.experiment` loads the rig; the CLI only builds a :class:`RigChoice`.
The names come from :mod:`drivers.registry` (each back-end's entry is light).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from drivers import registry
from drivers.rig import default_rig

#: ``--driver`` shortcuts: the robot back-end of the rig when no ``--rig`` is given.
DRIVERS = registry.driver_names()
#: The ``--driver`` of the built-in rig (:func:`drivers.rig.default_rig`'s robot).
DEFAULT_DRIVER = registry.robot_backend(default_rig().robot.type).driver
#: ``--ft`` values: the F/T back-end of the rig.
FT_SOURCES = registry.ft_types()
#: ``--tracker`` values: the rig's target tracker.
TRACKERS = registry.tracker_types()


@dataclass(frozen=True)
class RigChoice:
    """Which rig a run uses: a rig file (or the built-in sim rig) and field overrides.

    ``overrides`` are ``dotted.key=value`` strings on the rig's fields, e.g.
    ``robot.robot_ip=192.168.0.10``; the CLI turns its device flags into these.
    """

    path: Path | None = None
    overrides: tuple[str, ...] = ()
    driver: str | None = None
    """With no ``path``: the robot back-end of the built-in rig (a ``--driver`` name)."""
