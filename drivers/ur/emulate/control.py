"""A UR e-Series controller's force mode and pose servo on the simulated arm, in the world's terms.

What UR documents (URScript manual: ``force_mode``, ``force_mode_set_damping``,
``force_mode_set_gain_scaling``): on the *compliant* axes of the selection
vector the robot moves to achieve the commanded wrench, against the set
damping, with a speed cap; the other axes follow the commanded pose. UR does
not publish its force controller's law; the one here, per control cycle
(``scene.fri.cycle``, 2 ms for a UR) and per TCF axis ``i``:

- compliant: no stiffness; the wrench the arm applies is
  ``g F_cmd + (g - 1) w`` (``g`` the gain scaling, ``w`` the wrench the
  environment exerts on the tool, so that with ``g = 1`` the arm pushes with
  ``F_cmd`` and in steady contact ``-w = F_cmd`` for every ``g``), minus the
  damping ``Lambda_ii d / T v_i``: ``d`` (0..1, UR's ``damping``) is the
  fraction of the axis's speed ``v_i`` removed per cycle ``T`` (1: the arm
  decelerates at once with no force present, 0: it keeps its speed, as UR
  describes the parameter); ``Lambda_ii`` is the axis's own mass, the inverse of
  the diagonal of the Cartesian mobility ``J M^-1 J^T`` (a wrench on that axis
  alone). The wrench is clipped to what takes the axis to its speed cap
  within the cycle (beyond the cap: back to it);
- the others: a pose servo, the world's Cartesian spring at the scene's
  ``controller.cart_stiffness_max`` with damping ratio :data:`SERVO_DAMPING_RATIO`
  (the world realises it at every physics step; a real UR's servo is stiffer).
  Force mode's deviation limits on these axes are not modelled.

A *protective stop* latches when a joint reaches its position limit or moves
faster than its speed limit (the arm's description); from then on the arm is
held where it is with no wrench (:attr:`UrArmControl.stopped` says why).
No link protocol, no registers: :mod:`drivers.emulate` maps ffexp's URScript
program onto :class:`ForceModeCommand`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Final

import numpy as np

from drivers.base.types import F64
from drivers.world.arm import ArmCommand, ArmMode

if TYPE_CHECKING:
    from drivers.world.world import SimWorld

__all__ = ["SERVO_DAMPING_RATIO", "ForceModeCommand", "UrArmControl"]

#: The pose servo's damping ratio (our choice: the paper's KRC setting on its stiff axes).
SERVO_DAMPING_RATIO: Final = 0.7


@dataclass
class ForceModeCommand:
    """One cycle's command of a UR program: a pose servo, force mode on the compliant axes.

    ``pose_m``: the target TCP pose (4x4, base frame); ``compliant``: the selection
    vector per TCF axis (none: a pure pose servo); ``wrench_n_nm``: the wrench on the
    compliant axes (TCF); ``speed_limits_mps_radps``: their speed caps; ``damping``
    (0..1) and ``gain_scaling`` (0..2): UR's force-mode settings.
    """

    pose_m: F64
    compliant: np.ndarray = field(default_factory=lambda: np.zeros(6, dtype=bool))
    wrench_n_nm: F64 = field(default_factory=lambda: np.zeros(6))
    speed_limits_mps_radps: F64 = field(default_factory=lambda: np.full(6, np.inf))
    damping: float = 0.005
    gain_scaling: float = 1.0


class UrArmControl:
    """UR force mode and pose servo on ``world``'s arm (module docstring)."""

    def __init__(self, world: SimWorld) -> None:
        self.world = world
        lin, rot = world.scene.controller.cart_stiffness_max
        self._servo_k = np.array([lin] * 3 + [rot] * 3)
        self._servo_d = np.full(6, SERVO_DAMPING_RATIO)
        desc = world.scene.arm.description
        self._pos_limits = np.radians(desc.position_limits_deg)
        self._vel_limits = np.radians(desc.velocity_limits_degps)
        self._pos_limits_list: list[float] = self._pos_limits.tolist()
        self._vel_limits_list: list[float] = self._vel_limits.tolist()
        self._names = [f"joint {i + 1}" for i in range(desc.joints)]
        self._hold: F64 | None = None
        # each axis's own mass and mass per cycle (lam, lam / T), of the Cartesian inertia
        # whose bytes are the key: the world makes a new one when a joint has moved
        self._lam_of: tuple[bytes, float] | None = None
        self._lam: tuple[F64, F64] = (np.zeros(6), np.zeros(6))
        self._stiffness_of: bytes | None = None
        self._stiffness = self._servo_k
        self._twist_at = -1  # the world's cycle self._twist is of
        self._twist = np.zeros(6)
        self.stopped: str | None = None
        """Why a protective stop latched (``None``: none)."""

    def twist(self) -> F64:
        """The TCP's twist in the TCF at the current state [m/s, rad/s] (made once per
        cycle of the world: the outputs and the next command read it at the same state;
        do not modify)."""
        w = self.world
        if self._twist_at != w.cycle:
            jac = w.jacobian
            self._twist = np.asarray(jac @ w.data.qvel[:jac.shape[1]], dtype=np.float64)
            self._twist_at = w.cycle
        return self._twist

    def hold(self) -> ArmCommand:
        """Hold the arm where it is (the pose when the hold began), no wrench."""
        if self._hold is None:
            self._hold = self.world.tcp_pose.copy()
        return ArmCommand(mode=ArmMode.CART_IMPEDANCE, cart_pose_m=self._hold,
                          cart_stiffness_npm_nmprad=self._servo_k,
                          cart_damping_ratio=self._servo_d, tcp_wrench_n_nm=np.zeros(6))

    def command(self, cmd: ForceModeCommand | None) -> ArmCommand:
        """The world's command for the next cycle; ``None`` (or a protective stop) holds."""
        if cmd is None or self.stopped is not None:
            return self.hold()
        self._hold = None
        sel = np.asarray(cmd.compliant, dtype=bool)
        key = sel.tobytes()
        if key != self._stiffness_of:  # (the selection changes seldom)
            self._stiffness = np.where(sel, 0.0, self._servo_k)
            self._stiffness_of = key
        stiffness = self._stiffness
        wrench = np.zeros(6)
        if sel.any():
            w = self.world
            v = self.twist()
            # the axis's own mass: a wrench on it alone, the arm free within the cycle
            lam, per_speed = self._axis_mass(w.cart_inertia, w.cycle_s)
            ext = w.last_state.ext_wrench_n_nm
            g = cmd.gain_scaling
            push = g * np.asarray(cmd.wrench_n_nm) + (g - 1.0) * ext
            push -= lam * (min(max(cmd.damping, 0.0), 1.0) / w.cycle_s) * v
            # the speed cap: no more than takes the axis to it within the cycle
            cap = np.asarray(cmd.speed_limits_mps_radps)
            push = np.clip(push, per_speed * (-cap - v), per_speed * (cap - v))
            wrench = np.where(sel, push, 0.0)
        return ArmCommand(mode=ArmMode.CART_IMPEDANCE, cart_pose_m=np.asarray(cmd.pose_m),
                          cart_stiffness_npm_nmprad=stiffness,
                          cart_damping_ratio=self._servo_d, tcp_wrench_n_nm=wrench)

    def _axis_mass(self, cart_inertia: np.ndarray, cycle_s: float) -> tuple[F64, F64]:
        """``(lam, lam / T)``: each axis's own mass, ``1 / diag(Lambda^-1)``, made anew
        only when ``cart_inertia``'s bytes (or the cycle) changed: the 6x6 inverse was
        most of the law's cost."""
        key = (cart_inertia.tobytes(), cycle_s)
        if key != self._lam_of:
            lam = 1.0 / np.maximum(np.linalg.inv(cart_inertia).diagonal(), 1e-12)
            self._lam = (lam, lam / cycle_s)
            self._lam_of = key
        return self._lam

    def check_limits(self) -> str | None:
        """After a cycle: latch a protective stop if a joint is at its position limit or
        beyond its speed limit; return why (``None``: no stop)."""
        if self.stopped is None:
            # plain floats (the same values): numpy's scalars cost more than the test
            q, qd = self.world.arm_qpos.tolist(), self.world.arm_qvel.tolist()
            for name, qi, qdi, lim_q, lim_qd in zip(self._names, q, qd, self._pos_limits_list,
                                                    self._vel_limits_list, strict=True):
                if abs(qi) >= lim_q:
                    self.stopped = f"{name} at its position limit ({np.degrees(qi):.1f} deg)"
                elif abs(qdi) > lim_qd:
                    self.stopped = (f"{name} beyond its speed limit "
                                    f"({np.degrees(qdi):.1f} deg/s)")
                if self.stopped is not None:
                    break
        return self.stopped
