"""The world's state at the end of a cycle, built piece by piece when first read.

:class:`LazyArmState` is the :class:`~drivers.world.arm.ArmState` that
:attr:`SimWorld.last_state <drivers.world.world.SimWorld.last_state>` returns.
Its fields come in three groups, each computed from the world's MuJoCo data
on the first read of one of its fields:

* joints: ``jnt_pos_rad``, ``tcp_pose_m``, the set-points in use and ``warning``;
* dynamics: ``jacobian``, ``mass_matrix``, the joint torques, the external
  wrench and ``gravity_nm``;
* truth: ``truth`` (it also needs the Jacobian).

A cycle nobody reads costs no measurement; a reader of the joints pays
nothing for the Jacobian, mass matrix or truth. The values are those of the
cycle the state belongs to: before the world changes its data (the next
cycle, a new target velocity) it calls :meth:`LazyArmState.resolve` on a state
that is still referenced, which computes what was not read yet. Copies and
pickles are plain :class:`ArmState` objects with every field.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from drivers.world.arm import ArmMode, ArmState, ArmWarning
from drivers.world.truth import ground_truth, pose

if TYPE_CHECKING:
    from drivers.world.world import SimWorld

__all__ = ["LazyArmState"]

_WARN_TORQUE = int(ArmWarning.TORQUE_LIMIT)
_WARN_VELOCITY = int(ArmWarning.VELOCITY_LIMIT)
_WARN_POSITION = int(ArmWarning.POSITION_LIMIT)
_FIELDS = tuple(f.name for f in dataclasses.fields(ArmState))
_WARN_BITS = np.array((_WARN_VELOCITY, _WARN_POSITION, _WARN_TORQUE))
#: ArmWarning(bits) for every combination of the 4 bits (the same objects; a lookup
#: is cheaper than the enum's constructor)
_ARM_WARNINGS = tuple(
    ArmWarning(bits) for bits in range(1 << max(int(w) for w in ArmWarning).bit_length()))


class LazyArmState(ArmState):
    """An :class:`ArmState` of ``world``'s current cycle whose arrays are computed on
    first read (module docstring). ``cycle``, ``time_ns`` and ``mode`` are set now."""

    def __init__(self, world: SimWorld) -> None:  # not ArmState's: no field is built here
        self.cycle = world.cycle
        self.time_ns = world.cycle * world.cycle_ns
        self.mode = world.mode
        self._world: SimWorld | None = world

    def __getattr__(self, name: str) -> Any:
        # only for attributes not set yet: a group not computed yet
        fill = _FILL.get(name)
        world = self.__dict__.get("_world")
        if fill is None or world is None:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        fill(self, world)
        return self.__dict__[name]

    # ``warning`` has a class default in ArmState, so it cannot go through __getattr__
    @property
    def warning(self) -> ArmWarning:
        if "warning" not in self.__dict__:
            world = self.__dict__.get("_world")
            if world is None:
                return ArmWarning.NONE
            _fill_joints(self, world)
        value: ArmWarning = self.__dict__["warning"]
        return value

    @warning.setter
    def warning(self, value: ArmWarning) -> None:
        self.__dict__["warning"] = value

    def resolve(self) -> None:
        """Compute every field not read yet, now (the world is about to change)."""
        world = self.__dict__.get("_world")
        if world is None:
            return
        d = self.__dict__
        if "jnt_pos_rad" not in d:
            _fill_joints(self, world)
        if "jacobian" not in d:
            _fill_dynamics(self, world)
        if "truth" not in d:
            _fill_truth(self, world)
        self._world = None

    def __reduce__(self) -> tuple[Any, ...]:
        # copies and pickles: a plain ArmState with every field
        return (ArmState, (), {name: getattr(self, name) for name in _FIELDS})


def _fill_joints(s: LazyArmState, w: SimWorld) -> None:
    d = s.__dict__
    q = w._qpos_arm.copy()
    tcp = w.tcp_pose
    cart = s.mode == ArmMode.CART_IMPEDANCE
    d["jnt_pos_rad"] = q
    d["tcp_pose_m"] = tcp
    d["cmd_jnt_pos_rad"] = q.copy() if cart else w._jnt_pos.copy()
    d["cmd_cart_pose_m"] = w._cart_pos.copy() if cart else tcp.copy()
    # the limits, value by value (kernels.arm_warnings: |speed| > limit, position
    # beyond its limits, |torque| >= limit)
    warning = w._warning | w._arm_warnings(w._qvel_arm, q, w._actuator_arm, w._warn_limits,
                                           _WARN_BITS)
    d["warning"] = _ARM_WARNINGS[warning]


def _fill_dynamics(s: LazyArmState, w: SimWorld) -> None:
    d = s.__dict__
    w._kinematics()
    jac = w._jfull[:, w._va].copy()
    mass = w._mfull[w._va, w._va].copy()
    contact = w._contact
    tau_ext = jac.T @ contact
    # Link-side torque sensors: M qdd + c + g = tau_msr + tau_ext.
    tau_msr = mass @ w._qacc_arm
    tau_msr += w._bias_arm
    tau_msr -= tau_ext
    d["jacobian"] = jac
    d["mass_matrix"] = mass
    d["ext_jnt_trq_nm"] = tau_ext
    d["jnt_trq_nm"] = tau_msr
    d["ext_wrench_n_nm"] = contact.copy()
    d["gravity_nm"] = w._gravcomp_arm.copy()


def _fill_truth(s: LazyArmState, w: SimWorld) -> None:
    tcp_twist = s.jacobian @ w._qvel_arm
    sites = {"funnel_mouth": pose(w._mouth_xpos, w._mouth_xmat)}
    if w.chaser is not None:  # the TCP in the world (the state's is in the moving base's)
        sites["tcp"] = pose(w._tcp_xpos, w._tcp_xmat)
    d = w.data
    for name, site in w._object_sites:
        sites[name] = pose(d.site_xpos[site], d.site_xmat[site])
    s.__dict__["truth"] = ground_truth(
        w.bodies.truth(), sites,
        w._contact, w._touching, tcp_twist,
        None if w.chaser is None else w.chaser.arm_base_pose(), w._attached)


_FILL: dict[str, Callable[[LazyArmState, SimWorld], None]] = {
    "jnt_pos_rad": _fill_joints,
    "tcp_pose_m": _fill_joints,
    "cmd_jnt_pos_rad": _fill_joints,
    "cmd_cart_pose_m": _fill_joints,
    "jacobian": _fill_dynamics,
    "mass_matrix": _fill_dynamics,
    "jnt_trq_nm": _fill_dynamics,
    "ext_jnt_trq_nm": _fill_dynamics,
    "ext_wrench_n_nm": _fill_dynamics,
    "gravity_nm": _fill_dynamics,
    "truth": _fill_truth,
}
