"""FRI 1.x field conversions between wire order and our conventions, single or stacked.

Part of the codec (re-exported by :mod:`drivers.fri.codec`). FRI's 3x4
row-major frames become 4x4 matrices; the rotational half of wrenches,
Cartesian gains and Jacobian rows is ``(Z, Y, X)`` on the wire, ``(x, y, z)``
here.
"""

from __future__ import annotations

from typing import Final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from drivers.fri.codec.layout import NUM_JOINTS

_N = NUM_JOINTS

# --------------------------------------------------------------------------- field conversions

# Wire order of the rotational half of 6-vectors is (Z, Y, X) (FT, Jacobian
# rows, Cartesian gains A=Rz, B=Ry, C=Rx); ours is (x, y, z). The permutation
# swaps entries 3 and 5 and is its own inverse.
#: Index that swaps entries 3 and 5 of a 6-vector (wire <-> ours; its own inverse).
ROT_PERM: Final = np.array([0, 1, 2, 5, 4, 3], dtype=np.intp)
_ROT_PERM = ROT_PERM
_BOTTOM_ROW: Final = np.array([0.0, 0.0, 0.0, 1.0])


def _out_or_new(out: NDArray[np.float64] | None, shape: tuple[int, ...]) -> NDArray[np.float64]:
    if out is None:
        return np.empty(shape, dtype=np.float64)
    if out.shape != shape:
        raise ValueError(f"out has shape {out.shape}, expected {shape}")
    return out


def _last_axis(a: ArrayLike, n: int, what: str) -> NDArray[np.float64]:
    arr = np.asarray(a, dtype=np.float64)
    if arr.shape[-1:] != (n,):
        raise ValueError(f"{what}: last axis must have {n} entries, got shape {arr.shape}")
    return arr


def frame_to_matrix(
    frame: ArrayLike, out: NDArray[np.float64] | None = None
) -> NDArray[np.float64]:
    """FRI 3x4 row-major frame (12 floats, ``...x12``) -> 4x4 homogeneous matrix (``...x4x4``)."""
    f = _last_axis(frame, 12, "frame")
    res = _out_or_new(out, (*f.shape[:-1], 4, 4))
    res[..., :3, :] = f.reshape(*f.shape[:-1], 3, 4)
    res[..., 3, :] = _BOTTOM_ROW
    return res


def matrix_to_frame(
    matrix: ArrayLike, out: NDArray[np.float64] | None = None
) -> NDArray[np.float64]:
    """4x4 homogeneous matrix (``...x4x4``) -> FRI 3x4 row-major frame (``...x12``).

    The bottom row is dropped, not checked.
    """
    m = np.asarray(matrix, dtype=np.float64)
    if m.shape[-2:] != (4, 4):
        raise ValueError(f"matrix: last two axes must be 4x4, got shape {m.shape}")
    res = _out_or_new(out, (*m.shape[:-2], 12))
    res.reshape(*m.shape[:-2], 3, 4)[...] = m[..., :3, :]
    return res


def wrench_from_wire(ft: ArrayLike) -> NDArray[np.float64]:
    """Wire ``[Fx, Fy, Fz, Tz, Ty, Tx]`` -> ours ``[fx, fy, fz, tx, ty, tz]`` (``...x6``)."""
    return _last_axis(ft, 6, "wrench")[..., _ROT_PERM]


def wrench_to_wire(wrench: ArrayLike) -> NDArray[np.float64]:
    """Ours ``[fx, fy, fz, tx, ty, tz]`` -> wire ``[Fx, Fy, Fz, Tz, Ty, Tx]`` (``...x6``)."""
    return _last_axis(wrench, 6, "wrench")[..., _ROT_PERM]


def cart_gains_from_wire(gains: ArrayLike) -> NDArray[np.float64]:
    """``cartStiffness``/``cartDamping`` wire ``[x, y, z, A(Rz), B(Ry), C(Rx)]`` -> ours
    ``[x, y, z, rx, ry, rz]``."""
    return _last_axis(gains, 6, "cartesian gains")[..., _ROT_PERM]


def cart_gains_to_wire(gains: ArrayLike) -> NDArray[np.float64]:
    """Ours ``[x, y, z, rx, ry, rz]`` -> wire ``[x, y, z, A(Rz), B(Ry), C(Rx)]``."""
    return _last_axis(gains, 6, "cartesian gains")[..., _ROT_PERM]


def jacobian_from_wire(jac: ArrayLike) -> NDArray[np.float64]:
    """42 floats, row-major, rows ``X, Y, Z, RZ, RY, RX`` -> 6x7, rows ``x, y, z, rx, ry, rz``."""
    j = _last_axis(jac, 6 * _N, "jacobian")
    return j.reshape(*j.shape[:-1], 6, _N)[..., _ROT_PERM, :]


def jacobian_to_wire(jac: ArrayLike) -> NDArray[np.float64]:
    """6x7 with rows ``x, y, z, rx, ry, rz`` -> 42 wire floats (rows ``X, Y, Z, RZ, RY, RX``)."""
    j = np.asarray(jac, dtype=np.float64)
    if j.shape[-2:] != (6, _N):
        raise ValueError(f"jacobian: last two axes must be 6x{_N}, got shape {j.shape}")
    return j[..., _ROT_PERM, :].reshape(*j.shape[:-2], 6 * _N)


def mass_matrix_from_wire(mass: ArrayLike) -> NDArray[np.float64]:
    """49 floats, row-major -> 7x7."""
    m = _last_axis(mass, _N * _N, "massMatrix")
    return m.reshape(*m.shape[:-1], _N, _N).copy()


def mass_matrix_to_wire(mass: ArrayLike) -> NDArray[np.float64]:
    """7x7 -> 49 floats, row-major."""
    m = np.asarray(mass, dtype=np.float64)
    if m.shape[-2:] != (_N, _N):
        raise ValueError(f"massMatrix: last two axes must be {_N}x{_N}, got shape {m.shape}")
    return m.reshape(*m.shape[:-2], _N * _N).copy()
