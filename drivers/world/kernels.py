"""The world's per-cycle arithmetic, compiled (numba). Pure: no I/O, no clock.

Imported only when a world is built (numba's import costs about 0.4 s; ``ffexp --help``
never imports it). Compiled functions are cached on disk next to this module
(``cache=True``): a fresh checkout compiles them once (a few seconds), later processes
load them.

Bit for bit the numbers of the numpy form they replace: the same IEEE operations in the
same order, no fast-math (no contraction of ``a * b + c`` into a fused multiply-add
unless written as :func:`fma`). Where the numpy form went through BLAS, the products are
summed as OpenBLAS makes them (measured with numpy 2.4's wheels, OpenBLAS with FMA
kernels on x86-64): ``dgemm``, transposed ``dgemv`` and ``ddot`` take ``a0 b0``, then
fuse each further product in turn (:func:`dot3`; ``dgemm`` of ``k = 6``: the same, see
:func:`ft_block`); ``dgemv`` not transposed fuses ``a0 b0`` into ``a1 b1`` first
(:func:`dot3_n`). ``tests/test_world_kernels.py`` and ``tests/test_estimation_batch.py``
check them against numpy's own products on random inputs, so a numpy whose BLAS sums
otherwise shows there, not as a changed recording; the compiled form itself gives the
same bits on every machine (``llvm.fma`` rounds once, in hardware or in software).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from llvmlite import ir  # type: ignore[import-untyped]
from numba import njit, types
from numba.extending import intrinsic

from drivers.base.types import F64

__all__ = ["FT_BIAS", "FT_INV_RES", "FT_RANGE", "FT_RES", "FT_TARE", "FT_XFORM", "dot3",
           "dot3_n", "fma", "ft_block"]


def _fma_typing(typingctx, a, b, c):  # type: ignore[no-untyped-def]
    """``a * b + c`` rounded once (LLVM's ``llvm.fma.f64``)."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]
        d = ir.DoubleType()
        fn = builder.module.declare_intrinsic("llvm.fma", [d], ir.FunctionType(d, [d, d, d]))
        return builder.call(fn, args)

    return sig, codegen


fma: Any = intrinsic(_fma_typing)


@njit(cache=True)
def dot3(a0: float, a1: float, a2: float, b0: float, b1: float, b2: float) -> float:
    """``a . b`` as OpenBLAS's ``ddot``, ``dgemm`` and transposed ``dgemv`` make it."""
    return float(fma(a2, b2, fma(a1, b1, a0 * b0)))


@njit(cache=True)
def dot3_n(a0: float, a1: float, a2: float, b0: float, b1: float, b2: float) -> float:
    """``a . b`` as OpenBLAS's ``dgemv`` (not transposed) makes a row of ``A x``."""
    return float(fma(a2, b2, fma(a0, b0, a1 * b1)))


# ---------------------------------------------------------------- the F/T model

#: Rows of the F/T model's constants (``consts``, ``(11, 6)``): its bias, gauge range,
#: software tare, 1/resolution and resolution, then the 6x6 row-vector tool transform.
FT_BIAS, FT_RANGE, FT_TARE, FT_INV_RES, FT_RES, FT_XFORM = 0, 1, 2, 3, 4, 5


@njit(cache=True)
def ft_block(white: F64, i: int, raw: F64, delay_buf: F64, delay_n: int, drift: F64,
             consts: F64, tared: bool, out: F64, row_over: Any) -> int:
    """One block of the Net F/T model (``FtSensorModel.process``'s arithmetic).

    With ``delay_n > 0`` the readings first go through the delay buffer ``delay_buf``
    (``[held; newest]``, ``delay_n + n`` rows): its last ``delay_n`` rows move to its
    top, ``raw`` fills the rest, and its first ``n`` rows are the block's readings
    (``x``); otherwise ``x`` is ``raw``. Then
    ``out = rint((clip?((white[i:i+n] - x) + drift + bias) @ xform - tare?) *
    inv_res) * res`` for the ``n`` rows of ``raw`` (``n >= 2``: the product as
    OpenBLAS's ``dgemm`` sums it; a single row goes through ``dgemv``, whose order
    differs). The clip to the gauge range runs only when some value exceeds it (then
    ``row_over[r]`` is set per row, the number of such rows returned); the tare is
    subtracted only when ``tared``.
    """
    n = raw.shape[0]
    x = raw
    if delay_n > 0:
        for r in range(delay_n):  # forward: the source rows are below the target rows
            for c in range(6):
                delay_buf[r, c] = delay_buf[n + r, c]
        for r in range(n):
            for c in range(6):
                delay_buf[delay_n + r, c] = raw[r, c]
        x = delay_buf
    over = False
    for r in range(n):
        for c in range(6):
            v = white[i + r, c] - x[r, c]
            v += drift[r, c]
            v += consts[FT_BIAS, c]
            out[r, c] = v
            if abs(v) > consts[FT_RANGE, c]:
                over = True
    rows_over = 0
    if over:
        for r in range(n):
            flag = False
            for c in range(6):
                v = out[r, c]
                lim = consts[FT_RANGE, c]
                if abs(v) > lim:
                    flag = True
                # np.clip(v, -lim, lim): maximum, then minimum
                lo = -lim
                if v < lo:
                    v = lo
                if v > lim:
                    v = lim
                out[r, c] = v
            row_over[r] = flag
            if flag:
                rows_over += 1
    w = np.empty(6)
    for r in range(n):
        for c in range(6):
            w[c] = out[r, c]
        for j in range(6):
            acc = w[0] * consts[FT_XFORM, j]
            for k in range(1, 6):
                acc = fma(w[k], consts[FT_XFORM + k, j], acc)
            if tared:
                acc -= consts[FT_TARE, j]
            acc *= consts[FT_INV_RES, j]
            acc = np.rint(acc)
            acc *= consts[FT_RES, j]
            out[r, j] = acc
    return rows_over
