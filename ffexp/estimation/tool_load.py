"""Tool-load compensation and its identification. No I/O.

``w_load = [m R^T g, c x (m R^T g)]`` in the sensor frame for a tool of mass
``m`` with centre of mass ``c`` behind the sensor, and its least-squares
identification (with the bias) from static poses.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import Field

from drivers.base.types import F64
from drivers.config import StrictModel, Vec3

GRAVITY_BASE_MPS2: F64 = np.array([0.0, 0.0, -9.81])
"""Gravity in the robot base frame (base Z up). In the paper's TCF it is along -X."""


class ToolLoad(StrictModel):
    """Mass and centre of mass (sensor frame) of the tool the sensor carries.

    The reading, in our convention, is ``w = w_contact + w_load`` with
    ``w_load = [m R^T (g - a), c x m R^T (g - a)]``: the tool's weight and,
    while it accelerates by ``a`` (base frame), its inertia. Subtracting
    ``w_load`` leaves the contact wrench.
    """

    mass_kg: float = Field(0.0, ge=0)
    com_m: Vec3 = (0.0, 0.0, 0.0)
    gravity_mps2: float = Field(
        9.81, ge=0, description="The gravity the tool's weight is taken with, along the base "
        "frame's -Z [m/s^2]: 0 in orbit (a scene with physics.gravity = 0).")

    def gravity_base(self) -> F64:
        """Gravity in the robot base frame [m/s^2]."""
        return np.array([0.0, 0.0, -self.gravity_mps2])

    def wrench(
        self,
        r_base_sensor: F64,
        accel_base: F64 | None = None,
        gravity: F64 | None = None,
    ) -> F64:
        """Wrench the tool's weight (and inertia, given ``accel_base``) adds to the reading
        (``gravity``: :attr:`gravity_mps2` along -Z unless given)."""
        if gravity is None:
            gravity = self.gravity_base()
        g = gravity if accel_base is None else gravity - accel_base
        f = self.mass_kg * (r_base_sensor.T @ g)
        return np.concatenate([f, np.cross(np.asarray(self.com_m), f)])


def skew(v: F64) -> F64:
    """Cross-product matrix: ``skew(a) @ b == a x b``."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


@dataclass(frozen=True)
class ToolLoadFit:
    """Result of :func:`identify_tool_load`."""

    load: ToolLoad
    bias: F64
    residual_rms: F64


def identify_tool_load(
    rotations: F64, wrenches: F64, gravity: F64 = GRAVITY_BASE_MPS2
) -> ToolLoadFit:
    """Least-squares tool mass, centre of mass and sensor bias from static poses.

    Args:
        rotations: (K, 3, 3) sensor orientations in the base frame.
        wrenches: (K, 6) static readings (our sign convention).

    The model ``w = [m g_s, (m c) x g_s] + bias`` with ``g_s = R^T g`` is
    linear in ``(m, m c, bias)``; it needs at least three orientations that
    are not all rotations about the gravity axis.
    """
    rotations = np.asarray(rotations, dtype=np.float64)
    wrenches = np.asarray(wrenches, dtype=np.float64)
    k = rotations.shape[0]
    if k < 3 or wrenches.shape != (k, 6):
        raise ValueError("need >= 3 poses with one 6-vector each")
    a = np.zeros((6 * k, 10))
    for i in range(k):
        g_s = rotations[i].T @ gravity
        a[6 * i : 6 * i + 3, 0] = g_s
        a[6 * i : 6 * i + 3, 4:7] = np.eye(3)
        a[6 * i + 3 : 6 * i + 6, 1:4] = -skew(g_s)
        a[6 * i + 3 : 6 * i + 6, 7:10] = np.eye(3)
    sol, _res, rank, _sv = np.linalg.lstsq(a, wrenches.reshape(-1), rcond=None)
    if rank < 10:
        raise ValueError("poses do not excite every parameter: add different orientations")
    mass = float(sol[0])
    com = sol[1:4] / mass if abs(mass) > 1e-9 else np.zeros(3)
    residual = (a @ sol - wrenches.reshape(-1)).reshape(k, 6)
    return ToolLoadFit(
        load=ToolLoad(mass_kg=max(mass, 0.0), com_m=(float(com[0]), float(com[1]), float(com[2]))),
        bias=np.concatenate([sol[4:7], sol[7:10]]),
        residual_rms=np.sqrt(np.mean(residual**2, axis=0)),
    )


