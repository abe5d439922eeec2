"""Sums of products as OpenBLAS makes them, compiled (numba): for compiled code that
replaces a numpy product bit for bit. Pure: no I/O.

Imported only by compiled modules (numba's import costs about 0.4 s). Measured with
numpy 2.4's wheels (OpenBLAS with FMA kernels on x86-64): ``dgemm``, transposed
``dgemv`` and ``ddot`` fuse ``a0 b0``, ``a1 b1`` and ``a2 b2`` in turn (:func:`dot3`);
``dgemv`` not transposed fuses ``a1 b1``, ``a0 b0``, then ``a2 b2`` (:func:`dot3_n`).
Each starts from an accumulator of ``+0.0``: the first product's value is unchanged,
but a sum of signed zeros is ``+0.0``, as numpy's products give it (``a0 b0`` alone
may be ``-0.0``). ``tests/test_estimation_batch.py`` and
``tests/test_world_kernels.py`` check them against numpy's own products on random
inputs, so a numpy whose BLAS sums otherwise shows there, not as a changed recording;
the compiled form itself gives the same bits on every machine (``llvm.fma`` rounds
once, in hardware or in software).
"""

from __future__ import annotations

from typing import Any

from llvmlite import ir  # type: ignore[import-untyped]
from numba import njit, types
from numba.extending import intrinsic

from drivers.base.signatures import f8

__all__ = ["dot3", "dot3_n", "fma"]


def _fma_typing(typingctx, a, b, c):  # type: ignore[no-untyped-def]
    """``a * b + c`` rounded once (LLVM's ``llvm.fma.f64``)."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]
        d = ir.DoubleType()
        fn = builder.module.declare_intrinsic("llvm.fma", [d], ir.FunctionType(d, [d, d, d]))
        return builder.call(fn, args)

    return sig, codegen


fma: Any = intrinsic(_fma_typing)


@njit([(f8, f8, f8, f8, f8, f8)], cache=True)
def dot3(a0: float, a1: float, a2: float, b0: float, b1: float, b2: float) -> float:
    """``a . b`` as OpenBLAS's ``ddot``, ``dgemm`` and transposed ``dgemv`` make it:
    ``a0 b0``, ``a1 b1``, ``a2 b2`` fused in turn into ``+0.0``."""
    return float(fma(a2, b2, fma(a1, b1, fma(a0, b0, 0.0))))


@njit([(f8, f8, f8, f8, f8, f8)], cache=True)
def dot3_n(a0: float, a1: float, a2: float, b0: float, b1: float, b2: float) -> float:
    """``a . b`` as OpenBLAS's ``dgemv`` (not transposed) makes a row of ``A x``:
    ``a1 b1``, ``a0 b0``, ``a2 b2`` fused in turn into ``+0.0``."""
    return float(fma(a2, b2, fma(a0, b0, fma(a1, b1, 0.0))))
