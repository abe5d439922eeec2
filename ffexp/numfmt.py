"""Numbers for people: a value to the precision its uncertainty allows."""

from __future__ import annotations

import math


def decimals_for(std: float) -> int | None:
    """Decimal places that show two significant digits of ``std`` (None: no usable std)."""
    if not (math.isfinite(std) and std > 0.0):
        return None
    return max(0, 1 - math.floor(math.log10(std)))


def fixed(value: float, std: float) -> str:
    """``value`` to the decimal place of ``std``'s second significant digit."""
    d = decimals_for(std)
    return f"{value:.6g}" if d is None else f"{value:.{d}f}"


def pm(value: float, std: float) -> str:
    """``value ± std``, two significant digits of ``std`` (``0.00500010 ± 0.00000029``),
    never a ``± 0.00000`` that hides the uncertainty."""
    d = decimals_for(std)
    if d is None:
        return f"{value:.6g} ± {std:g}"
    return f"{value:.{d}f} ± {std:.{d}f}"
