"""MuJoCo's own C functions for compiled code: their addresses in the shared library
the ``mujoco`` package loaded, so a compiled kernel calls the very functions the Python
bindings call (with a model's and data's ``_address``), without a Python call each."""

from __future__ import annotations

import ctypes
from collections.abc import Sequence
from functools import cache
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

__all__ = ["function_addresses"]


@cache
def _library() -> ctypes.CDLL:
    import mujoco

    here = Path(mujoco.__file__).parent
    names = ("libmujoco.so*", "libmujoco*.dylib", "mujoco.dll")
    found = sorted(p for pattern in names for p in here.glob(pattern))
    if not found:
        raise RuntimeError(f"no MuJoCo shared library in {here}")
    return ctypes.CDLL(str(found[0]))


def function_addresses(names: Sequence[str]) -> NDArray[np.int64]:
    """The addresses of MuJoCo's functions ``names``, in that order."""
    lib = _library()
    return np.array([ctypes.cast(getattr(lib, name), ctypes.c_void_p).value for name in names],
                    dtype=np.int64)
