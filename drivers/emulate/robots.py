"""The robot controllers ``ffexp emulate`` can serve, and what each needs (light: no physics).

One entry per emulated controller: how its link runs (the KRC sends FRI
datagrams to a remote driver it is told of; a UR controller listens for RTDE
clients), where it listens by default, and the scene it serves when none is
given (the paper's rig, with this arm's overrides). The command line takes its
``--robot`` names and help from here, so a new emulated family is an entry
here and its server in :mod:`drivers.emulate.session`, not a change of the CLI.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import import_module
from typing import Literal

__all__ = ["ROBOTS", "EmulatedRobot", "robot_names"]


@dataclass(frozen=True)
class EmulatedRobot:
    """One controller the emulated rig can serve."""

    name: str
    what: str
    """One line for ``--help``."""
    link: Literal["fri", "rtde"]
    """``fri``: it sends to the remote driver (``--remote``); ``rtde``: it listens."""
    listen: tuple[str, int] | None
    """Where it listens by default (None: it does not listen, it sends)."""
    overrides_from: str | None
    """``module:NAME`` of the overrides that make the paper's rig this robot's default
    scene (None: the paper's rig as it is); read when asked, so that the command line's
    start does not load the description."""
    takes_cycle: bool
    """Its cycle is set on the command line (FRI's friOpen); else the scene's."""

    def scene_overrides(self) -> tuple[str, ...]:
        """The default scene: the paper's rig with these overrides."""
        if self.overrides_from is None:
            return ()
        module, name = self.overrides_from.split(":")
        return tuple(getattr(import_module(module), name))


ROBOTS: dict[str, EmulatedRobot] = {
    "lwr4": EmulatedRobot("lwr4", "a KRC2 LR over FRI 1.x (sends to --remote)", "fri", None,
                          None, True),
    "ur5e": EmulatedRobot("ur5e", "a UR e-Series controller over RTDE (listens on --listen, "
                          "default 127.0.0.1:30004)", "rtde", ("127.0.0.1", 30004),
                          "drivers.description.ur5e:PAPER_SCENE_OVERRIDES", False),
}


def robot_names() -> tuple[str, ...]:
    """The names ``--robot`` takes."""
    return tuple(ROBOTS)
