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

__all__ = ["ConfigError", "DriverError", "FfexpError", "InputError", "SimulationError"]


class InputError(FfexpError):
    """A data file (video, recording, CSV) cannot be used as given."""

    exit_code = 2
