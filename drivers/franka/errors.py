"""The Franka's stops as the project's errors, each in the robot's own words.

A reflex (the robot's safety stopping the motion: a collision, a joint limit, a torque
out of range, the link failing the robot's timing, ``communication_constraints_violation``)
is :class:`FrankaReflexError`, naming the robot's address and its error flags as
libfranka names them; libfranka's own exceptions are mapped by :func:`from_libfranka`
(its message kept): a refused or lost connection is a
:class:`~drivers.errors.LinkLostError`, an incompatible server version a
:class:`FrankaVersionError`, a control exception (a reflex during the loop) a
:class:`FrankaReflexError`.
"""

from __future__ import annotations

from drivers.errors import DriverError, LinkLostError

__all__ = ["FrankaReflexError", "FrankaVersionError", "from_libfranka"]


class FrankaReflexError(DriverError):
    """The robot stopped the motion with a reflex."""

    def __init__(self, address: str, errors: list[str], detail: str = "") -> None:
        self.address = address
        self.errors = list(errors)
        what = ", ".join(errors) if errors else "no error named"
        extra = f" ({detail})" if detail else ""
        super().__init__(f"franka {address}: reflex: {what}{extra}")


class FrankaVersionError(DriverError):
    """The robot speaks another protocol version than the client's libfranka."""


def from_libfranka(address: str, exc: BaseException) -> DriverError:
    """The project's error for an exception libfranka raised (its words kept, one line)."""
    kind = type(exc).__name__
    text = " ".join(str(exc).split())
    if kind == "IncompatibleVersionException":
        return FrankaVersionError(f"franka {address}: incompatible version: {text}")
    if kind in ("NetworkException", "ProtocolException", "RealtimeException"):
        return LinkLostError(f"franka {address}: {text}")
    if kind == "ControlException":
        words = (w.strip(',.:;"') for w in text.replace("[", " ").replace("]", " ").split())
        names = [w for w in words if w.islower() and "_" in w]
        return FrankaReflexError(address, names, text)
    return DriverError(f"franka {address}: {kind}: {text}")
