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
