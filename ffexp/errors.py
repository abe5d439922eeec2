"""Errors of the experiment layer.

The one exception hierarchy lives in :mod:`drivers.errors` (the bottom layer,
which cannot import ffexp). Its root :class:`FfexpError`, :class:`ConfigError`,
:class:`DriverError` and :class:`SimulationError` are re-exported here, so that
``from ffexp.errors import ...`` is the one place the experiment layer imports
its errors from, and ``except ffexp.errors.SimulationError`` also catches a
diverged physics simulation raised by a driver: there is one class, not two.
Only errors that the hardware layer never raises are defined here.
"""

from __future__ import annotations

from drivers.errors import ConfigError, DriverError, FfexpError, SimulationError

__all__ = ["ConfigError", "CorruptRecordingError", "DriverError", "FfexpError", "InputError",
           "SimulationError"]


class InputError(FfexpError):
    """A data file (video, recording, CSV) cannot be used as given."""

    exit_code = 2


class CorruptRecordingError(InputError):
    """A finished recording whose data is damaged: a chunk that does not decompress,
    whose CRC does not match, or whose records do not fit in it.

    Args:
        path: the recording.
        reason: what is damaged, in a few words (the chunk's number and byte offset
            where they are known).

    ``str(err)`` names the file and points to ``ffexp recover``, which rewrites every
    readable chunk into a new file.
    """

    def __init__(self, path: str, reason: str) -> None:
        self.path = path
        self.reason = reason
        super().__init__(f"{path}: corrupt data ({reason}); `ffexp recover {path}` rewrites "
                         "every readable chunk into a new file")

    def __reduce__(self) -> tuple[type[CorruptRecordingError], tuple[str, str]]:
        return (type(self), (self.path, self.reason))  # pickles across a process pool
