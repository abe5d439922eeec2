"""Scripted back-ends for tests and dry runs: replay states, record commands.

The names below are imported on first use (PEP 562): the back-end's entry
(:mod:`drivers.mock.backend`) is read by :mod:`drivers.registry` without them.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from drivers.mock.driver import MockFtSensor, MockRobot, NoisyFtSensor, stationary_robot

__all__ = ["MockFtSensor", "MockRobot", "NoisyFtSensor", "stationary_robot"]


def __getattr__(name: str) -> Any:
    if name not in __all__:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(import_module(f"{__name__}.driver"), name)
