"""The argument types the compiled kernels declare (numba), and the loading of every
compiled module of :mod:`drivers` before a real-time loop starts.

No compile inside a loop: every ``@njit`` of a kernels module names its signatures
(``@njit([(F1, F2)], cache=True)``). numba then compiles each of them, or loads it from
its disk cache, when the module is imported, and never compiles again: a call with other
argument types is a ``TypeError`` (after numba's safe conversions: a writable array
where a read-only one is declared, a C-contiguous one where any layout is), never a
compile in the middle of a cycle. Importing the modules (:func:`load_kernels`) before a
world serves its first cycle is then all a loop needs; a fresh checkout pays the compile
there, once (the cache keeps it). ``tests/test_kernels_ready.py`` checks that every
dispatcher of every kernels module has its compile disabled.

Imported only by compiled modules (numba's import costs about 0.4 s).
"""

from __future__ import annotations

from importlib import import_module
from types import ModuleType
from typing import Any

from numba import types

__all__ = [
    "B1",
    "F1",
    "F1A",
    "F2",
    "F2A",
    "F3",
    "I1",
    "I2",
    "I32_1A",
    "I32_2",
    "I32_2A",
    "KERNEL_MODULES",
    "RF1",
    "RF1A",
    "RF2",
    "RF2A",
    "RF3",
    "RI1",
    "RU1",
    "U1",
    "b1",
    "f8",
    "i8",
    "load_kernels",
]

#: The compiled modules of :mod:`drivers`, in their import order.
KERNEL_MODULES = ("drivers.base.blas", "drivers.world.kernels", "drivers.franka.kernels")


def _array(dtype: Any, ndim: int, layout: Any = "C", readonly: bool = False) -> Any:
    array: Any = types.Array  # (built without its typed overloads)
    return array(dtype, ndim, layout, readonly=readonly)


f8: Any = types.float64
i8: Any = types.int64
b1: Any = types.boolean
#: float64 arrays, C-contiguous, of 1, 2 and 3 dimensions
F1, F2, F3 = (_array(types.float64, n) for n in (1, 2, 3))
#: float64 arrays of any layout (a slice, a transpose)
F1A, F2A = (_array(types.float64, n, "A") for n in (1, 2))
#: read-only float64 arrays (a writable one converts to these)
RF1, RF2, RF3 = (_array(types.float64, n, readonly=True) for n in (1, 2, 3))
RF1A, RF2A = (_array(types.float64, n, "A", readonly=True) for n in (1, 2))
#: int64, uint32 and bool arrays, C-contiguous (``R``: read-only)
I1, I2 = (_array(types.int64, n) for n in (1, 2))
RI1 = _array(types.int64, 1, readonly=True)
U1 = _array(types.uint32, 1)
RU1 = _array(types.uint32, 1, readonly=True)
B1 = _array(types.boolean, 1)
#: int32 arrays (MuJoCo's contact fields: strided views of its contact structs)
I32_1A = _array(types.int32, 1, "A")
I32_2 = _array(types.int32, 2)
I32_2A = _array(types.int32, 2, "A")


def load_kernels() -> tuple[ModuleType, ...]:
    """Import :data:`KERNEL_MODULES`: every compiled function of :mod:`drivers` compiled,
    or loaded from numba's cache, now (seconds on a fresh checkout, a fraction of one
    after), so none does at a world's first cycle."""
    return tuple(import_module(name) for name in KERNEL_MODULES)
