"""The one exception hierarchy of ffexp, rooted in the bottom layer.

:mod:`drivers` must not import :mod:`ffexp`, so the root :class:`FfexpError`
lives here and ``ffexp.errors`` builds on it. Every error a user can cause
derives from it; the CLI turns it into one line on stderr (naming the file,
field, device, address or frame) and exits with :attr:`FfexpError.exit_code`.
"""

from __future__ import annotations


class FfexpError(Exception):
    """Root of all ffexp errors. ``str(err)`` is the one-line message."""

    exit_code: int = 1


class ConfigError(FfexpError):
    """A protocol, scene or settings file is missing, unreadable or invalid.

    Args:
        source: the file (or ``--set`` option) the problem is in.
        field: dotted path of the offending field, or ``""`` for the file itself.
        message: what is wrong, in one line.
    """

    exit_code = 2

    def __init__(self, source: str, field: str, message: str) -> None:
        self.source = source
        self.field = field
        self.message = message
        where = f"{source}: {field}" if field else source
        super().__init__(f"{where}: {message}")


class DriverError(FfexpError):
    """Root of every hardware-layer (device, link, simulator) error."""


class NotConnectedError(DriverError):
    """A device method was called before ``connect()`` or after ``close()``."""


class DriverTimeoutError(DriverError):
    """No data arrived from a device within its timeout."""


class LinkLostError(DriverError):
    """The link to a device was lost while running."""


class MalformedPacketError(DriverError):
    """A datagram from a device could not be decoded.

    Args:
        source: where the datagram came from: an address tuple as ``recvfrom``
            returns it (shown as ``"192.168.0.10:49938"``), a string, or
            ``None`` (shown as ``"<buffer>"``).
        reason: a short machine-readable code (``"too_short"``, ``"wrong_id"``, ...).
        message: what is wrong, in one line.
    """

    def __init__(self, source: object, reason: str, message: str) -> None:
        if source is None:
            where = "<buffer>"
        elif isinstance(source, tuple) and len(source) >= 2:
            where = f"{source[0]}:{source[1]}"
        else:
            where = str(source)
        self.source = where
        self.reason = reason
        self.message = message
        super().__init__(f"{where}: malformed packet ({reason}): {message}")


class PacketEncodeError(DriverError):
    """A value cannot be put on the wire (NaN, infinite, or out of the wire type's range).

    Args:
        field: the offending field, named as in the packet (``"cmd.jntPos"``).
        message: what is wrong, in one line.
    """

    def __init__(self, field: str, message: str) -> None:
        self.field = field
        self.message = message
        super().__init__(f"cannot encode {field}: {message}")


class InvalidCommandError(DriverError):
    """A command carried non-finite or malformed values (the KRC would drop to monitor mode)."""


class SimulationError(DriverError):
    """The physics simulation diverged or was driven outside what it models."""


class AddressError(DriverError):
    """A network address is malformed, cannot be resolved, or its port cannot be bound.

    Args:
        where: where the address came from, as the caller names it: a file and
            field (``"rigs/lwr4-lab.toml: robot.robot_ip"``) or a rig table's field
            (``"robot.robot_ip"``); never a command-line flag from
            inside :mod:`drivers`.
        address: the address as given.
        message: what is wrong, in one line.

    ``str(err)`` is ``"<where>: <address>: <message>"``.
    """

    exit_code = 2

    def __init__(self, where: str, address: str, message: str) -> None:
        self.where = where
        self.address = address
        self.message = message
        super().__init__(f"{where}: {address}: {message}")
