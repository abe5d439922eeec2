"""The one exception hierarchy of the experiment layer.

Every error a user can cause derives from :class:`FfexpError`; the CLI turns
it into one line on stderr and the exit code in :attr:`FfexpError.exit_code`.
The hardware layer (:mod:`drivers`) cannot import this module, so it has its
own root, ``drivers.errors.DriverError``; the CLI treats both alike.
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


class InputError(FfexpError):
    """A data file (video, recording, CSV) cannot be used as given."""

    exit_code = 2


class SimulationError(FfexpError):
    """A simulation cannot run with the parameters given (e.g. unstable step)."""

    exit_code = 1
