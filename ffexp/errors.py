"""Errors of the experiment layer.

The root :class:`FfexpError` and :class:`ConfigError` live in
:mod:`drivers.errors` (the bottom layer, which cannot import ffexp) and are
re-exported here, so that ``from ffexp.errors import ...`` is the one place
the experiment layer imports its errors from.
"""

from __future__ import annotations

from drivers.errors import ConfigError, DriverError, FfexpError

__all__ = ["ConfigError", "DriverError", "FfexpError", "InputError", "SimulationError"]


class InputError(FfexpError):
    """A data file (video, recording, CSV) cannot be used as given."""

    exit_code = 2


class SimulationError(FfexpError):
    """A simulation cannot run with the parameters given."""
