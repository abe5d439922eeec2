"""MuJoCo's own C functions for compiled code (numba): their addresses in the shared
library the ``mujoco`` package loaded (:func:`function_addresses`), and :func:`c_call`,
which calls one of them from compiled code, so a kernel calls the very functions the
Python bindings call (with a model's and data's ``_address``) without a Python call
each. Imported only by compiled modules (numba's import is slow)."""

from __future__ import annotations

import ctypes
from collections.abc import Sequence
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
from llvmlite import ir  # type: ignore[import-untyped]
from numba import types
from numba.extending import intrinsic
from numpy.typing import NDArray

__all__ = ["c_call", "function_addresses"]


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


def _c_type(ty: Any) -> Any:
    """The C type a compiled value is passed as: an ``int64`` is an address (a struct's
    ``_address``: ``void*``), an ``int32`` an ``int``, a ``float64`` a ``double``, a
    float64 array its data (``double*``)."""
    if isinstance(ty, types.Array) and ty.dtype == types.float64:
        return ir.DoubleType().as_pointer()
    if ty == types.int64:
        return ir.IntType(8).as_pointer()
    if ty == types.int32:
        return ir.IntType(32)
    if ty == types.float64:
        return ir.DoubleType()
    raise TypeError(f"c_call: no C argument for {ty}")


def _c_call_typing(typingctx, addr, args):  # type: ignore[no-untyped-def]
    """``f(*args)`` for the ``void`` C function at the address ``addr`` (:func:`_c_type`
    says how each of the tuple ``args`` is passed)."""
    arg_types: Any = args  # numba's type of the tuple: iterable over its members' types
    if not isinstance(args, types.BaseTuple):
        return None
    c_types = [_c_type(ty) for ty in arg_types]
    sig = types.void(types.int64, args)

    def codegen(context, builder, signature, llargs):  # type: ignore[no-untyped-def]
        values = []
        for k, ty in enumerate(signature.args[1]):
            v = builder.extract_value(llargs[1], k)
            if isinstance(ty, types.Array):
                v = builder.bitcast(context.make_array(ty)(context, builder, v).data,
                                    c_types[k])
            elif ty == types.int64:
                v = builder.inttoptr(v, c_types[k])
            values.append(v)
        fnty = ir.FunctionType(ir.VoidType(), c_types)
        builder.call(builder.inttoptr(llargs[0], fnty.as_pointer()), values)
        return context.get_dummy_value()

    return sig, codegen


#: ``c_call(addr, (arg, ...))`` in compiled code: MuJoCo's function at ``addr``
#: (:func:`function_addresses`) called with the tuple's values.
c_call: Any = intrinsic(_c_call_typing)
