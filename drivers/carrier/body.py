"""The rendered target: a rigid body in free flight, integrated once per carrier cycle from
the wrench the carrier measured. No I/O.

The state is the centre of mass' position and velocity and the body's orientation and
angular momentum, all in the world frame (the angular momentum is the one a
torque-free body keeps; the angular velocity follows from it and the inertia turned
with the body). The force is held over the cycle (zero-order hold); the integrators:

- ``"symplectic"``: semi-implicit Euler (velocity first, then position with the new
  velocity): it adds no energy of its own to a contact;
- ``"explicit"``: explicit Euler (position with the old velocity): it acts as one
  more cycle of delay (``docs/hil.md``).
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np

from drivers.base.types import F64

__all__ = ["FreeBody", "cross3", "rotation_exp", "rotation_log"]

Integrator = Literal["symplectic", "explicit"]


def cross3(a: F64, b: F64) -> F64:
    """``a x b`` of two 3-vectors (``np.cross`` costs ten times more on one pair)."""
    a0, a1, a2 = float(a[0]), float(a[1]), float(a[2])
    b0, b1, b2 = float(b[0]), float(b[1]), float(b[2])
    return np.array((a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0))


def rotation_exp(rotvec: F64) -> F64:
    """The rotation matrix of a rotation vector (Rodrigues)."""
    x, y, z = float(rotvec[0]), float(rotvec[1]), float(rotvec[2])
    angle = math.sqrt(x * x + y * y + z * z)
    if angle < 1e-12:
        return np.array([[1.0, -z, y], [z, 1.0, -x], [-y, x, 1.0]])
    s, c = math.sin(angle) / angle, (1.0 - math.cos(angle)) / (angle * angle)
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    out: F64 = np.eye(3) + s * k + c * (k @ k)
    return out


def rotation_log(rot: F64) -> F64:
    """The rotation vector of a rotation matrix (angles below pi)."""
    cos = max(-1.0, min(1.0, (float(np.trace(rot)) - 1.0) / 2.0))
    angle = math.acos(cos)
    axis = np.array([rot[2, 1] - rot[1, 2], rot[0, 2] - rot[2, 0], rot[1, 0] - rot[0, 1]])
    if angle < 1e-9:
        return 0.5 * axis
    return angle / (2.0 * math.sin(angle)) * axis


class FreeBody:
    """A rigid body without gravity, moved by the wrench it is given.

    Args:
        mass_kg: its mass.
        inertia: its 3x3 inertia tensor about the centre of mass, body frame [kg m^2].
        position_m, rotation: its start pose (world frame).
        velocity_mps, angular_radps: its start twist (world frame).
    """

    def __init__(self, mass_kg: float, inertia: F64, position_m: F64, rotation: F64,
                 velocity_mps: F64, angular_radps: F64) -> None:
        self.mass_kg = float(mass_kg)
        self.inertia = np.array(inertia, dtype=np.float64)
        self._inertia_inv = np.linalg.inv(self.inertia)
        self.position_m = np.array(position_m, dtype=np.float64)
        self.rotation = np.array(rotation, dtype=np.float64)
        self.velocity_mps = np.array(velocity_mps, dtype=np.float64)
        self.momentum = self.rotation @ self.inertia @ self.rotation.T @ np.asarray(
            angular_radps, dtype=np.float64)
        """Angular momentum about the centre of mass, world frame [kg m^2/s]."""
        self.acceleration_mps2 = np.zeros(3)
        """The centre of mass' acceleration over the last step."""

    @property
    def angular_radps(self) -> F64:
        """The angular velocity, world frame."""
        r = self.rotation
        return np.asarray(r @ (self._inertia_inv @ (r.T @ self.momentum)))

    @property
    def mass_matrix(self) -> F64:
        """The 6x6 mass matrix (mass, inertia turned into the world frame)."""
        out = np.zeros((6, 6))
        out[:3, :3] = self.mass_kg * np.eye(3)
        out[3:, 3:] = self.rotation @ self.inertia @ self.rotation.T
        return out

    def kinetic_energy_j(self, frame_velocity_mps: F64 | None = None) -> float:
        """Kinetic energy, in a frame moving at ``frame_velocity_mps`` (default: at rest)."""
        v = self.velocity_mps if frame_velocity_mps is None else (
            self.velocity_mps - frame_velocity_mps)
        w = self.angular_radps
        return 0.5 * self.mass_kg * float(v @ v) + 0.5 * float(w @ self.momentum)

    def step(self, force_n: F64, torque_nm: F64, dt_s: float,
             integrator: Integrator = "symplectic") -> None:
        """Advance ``dt_s`` with the wrench (world frame, about the centre of mass) held."""
        accel = np.asarray(force_n, dtype=np.float64) / self.mass_kg
        if integrator == "explicit":
            self.position_m = self.position_m + self.velocity_mps * dt_s
            self.rotation = rotation_exp(self.angular_radps * dt_s) @ self.rotation
            self.velocity_mps = self.velocity_mps + accel * dt_s
            self.momentum = self.momentum + np.asarray(torque_nm) * dt_s
        else:
            self.velocity_mps = self.velocity_mps + accel * dt_s
            self.momentum = self.momentum + np.asarray(torque_nm) * dt_s
            self.position_m = self.position_m + self.velocity_mps * dt_s
            self.rotation = rotation_exp(self.angular_radps * dt_s) @ self.rotation
        self.acceleration_mps2 = accel
