"""Joint friction of the simulated LWR4+: a Stribeck curve on top of MuJoCo's dry friction.

Per joint, the friction torque that opposes a joint speed ``v`` is

    tau_f(v) = tau_c + (tau_s - tau_c) * exp(-(|v| / v_s) ** delta) + b * |v|

(static level ``tau_s`` at rest, falling smoothly to the Coulomb level
``tau_c`` above the Stribeck speed ``v_s``, plus viscous ``b``). MuJoCo holds
the dry part as a ``frictionloss`` constraint (a soft, regularised Coulomb
friction that sticks below its level and saturates at it) and the viscous
part as joint ``damping`` (integrated implicitly). :class:`JointFriction`
sets the constraint's level from the joint speed once per control cycle, so
a joint at rest must be pushed past ``tau_s`` to break away and then slides
against the lower ``tau_c``; the level is a continuous function of speed,
not a switch.

Pure maths and a write into the model's ``dof_frictionloss``; no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from drivers.base.types import F64
from drivers.description.scene import ArmSettings

__all__ = ["JointFriction"]


@dataclass
class JointFriction:
    """Stribeck friction of the first ``n`` joints (the arm's, DOF addresses 0..n-1).

    Attributes:
        static_nm: breakaway (static) level per joint [N m].
        coulomb_nm: sliding (Coulomb) level per joint [N m].
        viscous_nmsprad: viscous coefficient per joint [N m s/rad].
        stribeck_radps: Stribeck speed per joint [rad/s].
        shape: Stribeck exponent (2: Gaussian; 1: exponential).
    """

    static_nm: F64
    coulomb_nm: F64
    viscous_nmsprad: F64
    stribeck_radps: F64
    shape: float = 2.0

    def __post_init__(self) -> None:
        self.static_nm = np.asarray(self.static_nm, dtype=np.float64)
        self.coulomb_nm = np.asarray(self.coulomb_nm, dtype=np.float64)
        self.viscous_nmsprad = np.asarray(self.viscous_nmsprad, dtype=np.float64)
        self.stribeck_radps = np.maximum(np.asarray(self.stribeck_radps, dtype=np.float64), 1e-12)
        self._excess = self.static_nm - self.coulomb_nm
        self._n = int(self.static_nm.shape[0])
        self._work = np.zeros(self._n)
        from drivers.world import kernels  # numba: imported when a friction is made

        self._arg, self._level = kernels.stribeck_arg, kernels.stribeck_level

    @classmethod
    def of_arm(cls, arm: ArmSettings) -> JointFriction:
        """The friction a scene's arm settings give (its Coulomb and viscous levels,
        static over Coulomb ratio and Stribeck speed)."""
        coulomb = np.asarray(arm.coulomb_friction())
        return cls(
            static_nm=arm.static_ratio * coulomb,
            coulomb_nm=coulomb,
            viscous_nmsprad=np.asarray(arm.viscous_friction()),
            stribeck_radps=np.full(len(coulomb), arm.stribeck_speed),
        )

    @property
    def joints(self) -> int:
        """How many joints (DOF addresses 0..n-1) the friction acts on."""
        return self._n

    def dry_level_nm(self, speed_radps: F64) -> F64:
        """The dry (static-to-Coulomb) level at joint speed ``speed_radps`` [N m]."""
        # beyond 40 Stribeck speeds the excess is below 1e-600: clip (a diverging
        # state's huge speeds would overflow the power)
        v = np.minimum(np.abs(np.asarray(speed_radps, dtype=np.float64)) / self.stribeck_radps,
                       40.0)
        return self.coulomb_nm + self._excess * np.exp(-(v**self.shape))

    def torque_nm(self, speed_radps: F64) -> F64:
        """Magnitude of the whole friction torque at a steady joint speed [N m]."""
        v = np.abs(np.asarray(speed_radps, dtype=np.float64))
        return self.dry_level_nm(v) + self.viscous_nmsprad * v

    def install(self, model: mujoco.MjModel, first_dof: int = 0) -> None:
        """Write the viscous part and the level at rest into a compiled model (the arm's
        dofs from ``first_dof``)."""
        arm = slice(first_dof, first_dof + self._n)
        model.dof_damping[arm] = self.viscous_nmsprad
        model.dof_frictionloss[arm] = self.static_nm

    def apply(self, model: mujoco.MjModel, qvel: F64) -> None:
        """Set the dry level from the current joint speeds (call once per control cycle)."""
        n = self._n
        self.apply_into(qvel[:n], model.dof_frictionloss[:n])

    def apply_into(self, speed_radps: F64, out: F64) -> None:
        """:meth:`dry_level_nm` of ``speed_radps`` (``n`` values) written into ``out``
        (the model's ``dof_frictionloss[:n]``), bit for bit, without temporaries."""
        v = self._work
        if self.shape == 2.0 or self.shape == 1.0:  # compiled, but numpy's exp
            self._arg(speed_radps, self.stribeck_radps, self.shape == 2.0, v)
            np.exp(v, out=v)
            self._level(self.coulomb_nm, self._excess, v, out)
            return
        np.abs(speed_radps, out=v)
        np.divide(v, self.stribeck_radps, out=v)
        np.minimum(v, 40.0, out=v)
        _power(v, self.shape)
        np.negative(v, out=v)
        np.exp(v, out=v)
        np.multiply(self._excess, v, out=v)
        np.add(self.coulomb_nm, v, out=out)


def _power(v: F64, shape: float) -> None:
    """``v = v ** shape`` in place, as numpy's ``**`` computes it (a square for 2)."""
    if shape == 2.0:
        np.square(v, out=v)
    elif shape != 1.0:
        np.power(v, shape, out=v)
