"""Compensation of the rendering loop's energy gain: the time-domain passivity observer
and controller on the rendered target's port (Ryu and Hannaford) and the virtual
compliance EPOS uses. No I/O.

The port's energy audit, kept in the chaser's frame (where the contact is passive).
The physical contact does work on the mock-up, ``E_phys = sum f . v dt`` over the F/T
samples (the compensated wrench with the flange's twist at each sample's time); the
rendered body's kinetic energy changes by ``E_virt``. A lossless rendering has
``E_virt = E_phys``: the body leaves with what it brought less what the contact took.
Every delay of the loop makes ``E_virt`` larger (the force acts later than the motion
it answers), and ``E_virt - E_phys`` is the energy the loop generated (the observer).
The controller adds a damping wrench ``-beta M v`` (``M`` the body's mass matrix) on
the rendered body whenever the audit, with this cycle's power included, would show
generated energy, ``beta = (E_virt - E_phys) / (T v.Mv)`` (not below a speed of
1 mm/s, where it would be unbounded), and counts what it dissipates. (An audit of the
rebound alone, the body's energy rises against the contact's positive work, lets
the energy the loop lends the contact while it is compressed through: measured, it
leaves the restitution 12 to 40 % above the true one at 0 to 3 cycles of delay.)
"""

from __future__ import annotations

import math

import numpy as np

from drivers.base.types import F64

__all__ = ["PassivityController", "VirtualCompliance"]

#: Below this squared port speed [m^2/s^2] the controller adds no damping (1 mm/s).
MIN_SPEED2 = 1e-6


class PassivityController:
    """The observer and (when ``active``) the controller of one rendered body's port.

    Args:
        active: False: observe only (``compensation = "none"``: the record still shows
            the energy the loop generates).
    """

    def __init__(self, *, active: bool) -> None:
        self.active = active
        self.returned_j = 0.0
        """Work the physical contact did on the mock-up (``E_phys``)."""
        self.given_j = 0.0
        """The rendered body's kinetic energy change (``E_virt``)."""
        self.dissipated_j = 0.0
        """Energy the controller's damping took out."""
        self._energy_j: float | None = None

    @property
    def generated_j(self) -> float:
        """The observer: ``E_virt - E_phys`` (> 0: the loop generated energy)."""
        return self.given_j - self.returned_j

    def physical(self, wrench: F64, twist: F64, dt_s: float) -> None:
        """One F/T sample's work: the wrench on the mock-up and the flange's twist then."""
        self.returned_j += float(wrench @ twist) * dt_s

    def control(self, wrench: F64, twist: F64, energy_j: float, cycle_s: float,
                mass: F64) -> F64:
        """The wrench to give the rendered body this cycle (``wrench`` plus the damping).

        Args:
            wrench: the measured wrench the loop would apply (world, about the com).
            twist: the rendered body's twist now (in the chaser's frame).
            energy_j: the rendered body's kinetic energy now (same frame).
            cycle_s: the cycle.
            mass: the rendered body's 6x6 mass matrix (world frame): the damping is
                ``-beta M v``, the same rate of decay on every axis, and takes at most
                the body's whole velocity in one cycle (``beta <= 1 / T``; more would
                reverse it and give energy back); the rest waits for the next cycle.
        """
        self.observe(energy_j)
        excess = self.generated_j + max(0.0, float(wrench @ twist)) * cycle_s
        momentum = mass @ twist
        weight = float(twist @ momentum)  # twice the kinetic energy
        if (not self.active or excess <= 0.0
                or float(twist[:3] @ twist[:3]) + float(twist[3:] @ twist[3:]) < MIN_SPEED2):
            return wrench
        beta = min(excess / (cycle_s * weight), 1.0 / cycle_s)
        self.dissipated_j += beta * weight * cycle_s
        return np.asarray(wrench - beta * momentum)

    def observe(self, energy_j: float) -> None:
        """The rendered body's kinetic energy now (its change since the last call is
        added to ``E_virt``)."""
        if self._energy_j is not None:
            self.given_j += energy_j - self._energy_j
        self._energy_j = energy_j


class VirtualCompliance:
    """A virtual spring-damper between the rendered body and the mock-up: the flange is
    set ``o`` from the body, ``c o' + k o = f`` for the measured force ``f`` (the mock-up
    yields as if on a spring and damper), so the contact the loop closes around is the
    series of the real one and the virtual one, softer and slower, and the delay's share
    of a contact's period smaller. The damper keeps the measured force's rate (the real
    contact's damping) out of the set-point, where the delay would make it unstable.

    Args:
        stiffness_npm, damping_nspm: the spring and the damper.
    """

    def __init__(self, stiffness_npm: float, damping_nspm: float) -> None:
        self.stiffness_npm, self.damping_nspm = stiffness_npm, damping_nspm
        self.offset_m = np.zeros(3)
        self.rate_mps = np.zeros(3)

    def update(self, force_n: F64, cycle_s: float) -> None:
        """Advance the spring-damper ``c o' + k o = f`` one cycle with ``f`` held (exact)."""
        target = np.asarray(force_n, dtype=np.float64) / self.stiffness_npm
        decay = math.exp(-self.stiffness_npm / self.damping_nspm * cycle_s)
        new = target + (self.offset_m - target) * decay
        self.rate_mps = (new - self.offset_m) / cycle_s
        self.offset_m = new
