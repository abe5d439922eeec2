"""Every compiled kernel a run calls, loaded before the robot connects.

The kernels (numba) declare their signatures (:mod:`drivers.base.signatures`): importing
their modules compiles each, or loads it from numba's disk cache, and none compiles
later. :func:`load_kernels` imports them all, so that a run's loop (``ffexp.loop``,
``ffexp.calibrate.resim``) calls no kernel that still has to load: the first contact of
the first run after an install would otherwise stall a 5 ms cycle for seconds (a real
controller drops the link). This module imports numba only when called (``ffexp --help``
must stay fast).
"""

from __future__ import annotations

from importlib import import_module
from types import ModuleType

__all__ = ["KERNEL_MODULES", "load_kernels"]

#: ffexp's compiled modules (drivers' are :data:`drivers.base.signatures.KERNEL_MODULES`).
KERNEL_MODULES = ("ffexp.controllers.kernels", "ffexp.estimation.kernels")


def load_kernels() -> tuple[ModuleType, ...]:
    """Import every compiled module of :mod:`drivers` and of ffexp (about 20 s of CPU on
    a fresh checkout, which compiles them; about 0.5 s once numba's cache holds them, less
    when a world already loaded its own)."""
    from drivers.base.signatures import load_kernels as load_drivers

    return (*load_drivers(), *(import_module(name) for name in KERNEL_MODULES))
