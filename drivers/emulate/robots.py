"""The robot controllers ``ffexp emulate`` can serve: the families' entries in the registry.

Each family declares its emulated controller in its back-end entry
(:class:`~drivers.base.backend.Emulator`: its ``--robot`` name, whether it sends to a
remote driver or listens, where by default, its default scene and its own faults); the
command line takes its ``--robot`` names and help from here, so a new emulated family is
an entry in its own folder, not a change of the CLI or of this package.
"""

from __future__ import annotations

from drivers import registry
from drivers.base.backend import Emulator

__all__ = ["EmulatedRobot", "default_robot", "robot", "robot_names"]

#: One controller the emulated rig can serve (the registry's entry).
EmulatedRobot = Emulator


def robot_names() -> tuple[str, ...]:
    """The names ``--robot`` takes."""
    return tuple(e.name for e in registry.emulators())


def default_robot() -> str:
    """``--robot``'s default: the first family's controller."""
    return registry.emulators()[0].name


def robot(name: str) -> Emulator:
    """The controller ``--robot name`` (KeyError if none)."""
    return registry.emulator(name)
