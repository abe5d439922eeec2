"""Errors of the hardware layer.

:mod:`drivers` must not import :mod:`ffexp`, so this is the hardware branch of
ffexp's one exception hierarchy; the CLI reports :class:`DriverError` exactly
like ``ffexp.errors.FfexpError``: one line naming the device, address or frame,
and the exit code in :attr:`DriverError.exit_code`.
"""

from __future__ import annotations


class DriverError(Exception):
    """Root of every hardware-layer error; ``str(err)`` is the one-line message."""

    exit_code: int = 1


class NotConnectedError(DriverError):
    """A device method was called before ``connect()`` or after ``close()``."""


class DriverTimeoutError(DriverError):
    """No data arrived from a device within its timeout."""


class LinkLostError(DriverError):
    """The link to a device was lost while running."""


class ConfigurationError(DriverError):
    """A scene, model or device setting is invalid (names the file and field)."""

    exit_code = 2
