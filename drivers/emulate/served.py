"""What a family's emulated controller is to the emulated rig: :class:`ServedRobot`.

A family's :class:`~drivers.base.backend.Emulator` entry names a function
``serve(world, settings, ft_box) -> ServedRobot`` (``drivers/<family>/emulate/served.py``);
:class:`~drivers.emulate.session.EmulatedRig` calls it with the world it built, the rig's
settings and the Net F/T box it opened (if the entry asks for one), and from then on
knows the controller only through this protocol, so a new family's controller is served
without a change here.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

__all__ = ["ServedRobot"]


class ServedRobot(Protocol):
    """A robot controller serving its link on a simulated world."""

    @property
    def address(self) -> tuple[str, int]:
        """Where its link is bound (host, port)."""
        ...

    def ready_line(self) -> str:
        """One line: where it serves, to whom, its cycle and pacing."""
        ...

    def serve(self, stop_requested: Callable[[], bool], on_status: Callable[[str], None] | None,
              on_cycle: Callable[[], None], max_cycles: int | None, duration_s: float) -> Any:
        """Serve until ``max_cycles`` world steps, ``stop_requested()`` or an error (raised
        in the caller's thread); ``duration_s`` (> 0) also bounds the wall time a client
        never comes. ``on_cycle()`` is called between world steps (never during one);
        ``on_status`` gets a line now and then. Returns the controller's counters, if it
        keeps any."""
        ...

    def stop(self) -> None:
        """Ask it to stop after the current cycle (thread-safe)."""
        ...

    def close(self) -> None:
        """Stop serving and close its sockets (and the Net F/T box it was given)."""
        ...

    def summary(self) -> str:
        """Its counters in one line (also after :meth:`close`)."""
        ...
