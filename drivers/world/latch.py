"""Latching a command into the simulated world: each field the command gives is checked
and kept for the cycles that follow (the KRC holds a command until the next). No I/O.

A pose, stiffness or wrench whose bytes equal the latched one's (the pose: its
values' bits, compared by :func:`drivers.world.kernels.same_or_finite`) keeps the latched
object, so the world's actuators need no rewrite (:meth:`SimWorld._apply
<drivers.world.world.SimWorld>` compares objects).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from drivers.base.impedance import clip_cart_stiffness
from drivers.base.types import F64
from drivers.errors import InvalidCommandError
from drivers.world.arm import ArmCommand, ArmMode, ArmWarning

if TYPE_CHECKING:
    from drivers.world.world import SimWorld

__all__ = ["take"]

_WARN_CLIPPED = int(ArmWarning.STIFFNESS_CLIPPED)
_isfinite = math.isfinite


def _all_finite(a: F64) -> bool:
    """Every value of a small array finite (plain floats: cheaper than numpy for a few)."""
    return all(map(_isfinite, a.ravel().tolist()))


def take(w: SimWorld, cmd: ArmCommand) -> None:
    """Latch the fields ``cmd`` gives into the world ``w`` (the others keep their values).

    Raises:
        InvalidCommandError: a given field is not finite or has the wrong shape; the
            fields before it were latched.
    """
    w._latched = True
    if cmd.mode is not None and cmd.mode != w.mode:
        if cmd.mode not in (ArmMode.CART_IMPEDANCE, ArmMode.JOINT_POSITION,
                            ArmMode.JOINT_IMPEDANCE):
            raise InvalidCommandError(f"control mode {cmd.mode!r} not supported")
        w.mode = ArmMode(cmd.mode)
        w._cart_pos = w.tcp_pose.copy()
        w._jnt_pos = w.data.qpos[w._qa].copy()
    w._warning = 0
    # A pose or wrench with the bytes of the latched one keeps the latched object
    # (validated already; the actuators then need no rewrite).
    if cmd.cart_pose_m is not None:
        p = np.asarray(cmd.cart_pose_m, dtype=np.float64)
        if p.shape != (4, 4):
            raise InvalidCommandError("cart_pos must be a finite 4x4 pose")
        # compiled: the bits of the latched pose (0: kept), else finite (1) or not (2)
        change = w._same_or_finite(p, w._cart_pos)
        if change:
            if change == 2:
                raise InvalidCommandError("cart_pos must be a finite 4x4 pose")
            w._cart_pos = np.array(p)
    if cmd.cart_stiffness_npm_nmprad is not None:
        k = np.asarray(cmd.cart_stiffness_npm_nmprad, dtype=np.float64)
        key = k.tobytes()
        given = w._given_k
        if given is None or given[0] != key or k.shape != (6,):
            if k.shape != (6,) or not _all_finite(k):
                raise InvalidCommandError("cart_stiffness must be 6 finite values")
            mx = w.scene.controller.cart_stiffness_max
            clipped_k, clipped = clip_cart_stiffness(k, mx[0], mx[1])
            given = w._given_k = (key, clipped_k, clipped)
        w._cart_stiff = given[1]
        if given[2]:
            w._warning |= _WARN_CLIPPED
    if cmd.cart_damping_ratio is not None:
        dr = np.asarray(cmd.cart_damping_ratio, dtype=np.float64)
        key = dr.tobytes()
        given_d = w._given_d
        if given_d is None or given_d[0] != key or dr.shape != (6,):
            given_d = w._given_d = (
                key, np.clip(_finite(dr, 6, "cart_damping"), 0.0, 1.0))
        w._cart_damp = given_d[1]
    if cmd.tcp_wrench_n_nm is not None:
        ft = np.asarray(cmd.tcp_wrench_n_nm, dtype=np.float64)
        key = ft.tobytes()
        if key != w._tcp_ft_key or ft.shape != (6,):
            w._tcp_ft = _finite(ft, 6, "add_tcp_ft")
            w._tcp_ft_key = key
    if cmd.jnt_pos_rad is not None:
        w._jnt_pos = np.clip(_finite(cmd.jnt_pos_rad, w._n, "jnt_pos"),
                                w._pos_lower, w._pos_limits)
    if cmd.jnt_trq_nm is not None:
        w._jnt_trq = _finite(cmd.jnt_trq_nm, w._n, "add_jnt_trq")
    if cmd.jnt_stiffness_nmprad is not None:
        k = _finite(cmd.jnt_stiffness_nmprad, w._n, "jnt_stiffness")
        w._jnt_stiff = np.clip(k, 0.0, w.scene.controller.jnt_stiffness_max)
        if np.any(w._jnt_stiff != k):
            w._warning |= _WARN_CLIPPED
    if cmd.jnt_damping_ratio is not None:
        w._jnt_damp = np.clip(
            _finite(cmd.jnt_damping_ratio, w._n, "jnt_damping"), 0.0, 1.0)


def _finite(v: F64, n: int, name: str) -> F64:
    a = np.array(v, dtype=np.float64)
    if a.shape != (n,) or not _all_finite(a):
        raise InvalidCommandError(f"{name} must be {n} finite values")
    return a
