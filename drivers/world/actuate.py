"""Writing the world's latched command into MuJoCo: actuator parameters, the commanded
frame (mocap), the superposed wrench and joint torques, and the held Coriolis and
centrifugal forces (the KRC's laws: :mod:`drivers.world.world`'s docstring). No I/O.

Each Cartesian parameter is rewritten only when its inputs are other objects than those
last written (:mod:`drivers.world.latch` keeps an object while its bytes repeat).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from drivers.base.impedance import normalized_damping
from drivers.world.arm import ArmMode

if TYPE_CHECKING:
    from drivers.world.world import SimWorld

__all__ = ["apply"]


def apply(w: SimWorld) -> None:
    """Write the held command into actuators, mocap and applied forces."""
    # MuJoCo's arrays are looked up only where written (each lookup makes a view)
    if w.mode == ArmMode.CART_IMPEDANCE:
        # Each parameter is rewritten only when its inputs are other objects than
        # those last written (a given field is a new array; a repeated gain the same).
        written = w._written
        if w._latched or w._inertia_new:  # the damping: its inputs changed
            if (w._inertia_new or written.get("k_d") is not w._cart_stiff
                    or written.get("d") is not w._cart_damp):
                _write_cart_damping(w)
            w._inertia_new = False
        if w._latched:  # the rest changes only with a command
            w._latched = False
            if written.get("pos") is not w._cart_pos:
                # mocap_pos = the translation, mju_mat2Quat(mocap_quat, the rotation)
                w._set_frame(w._mj[0], w._cart_pos, w._mocap_pos, w._mocap_quat, w._rot9)
                written["pos"] = w._cart_pos
            if written.get("k") is not w._cart_stiff:
                np.negative(w._cart_stiff, out=w._cart_stiff_prm)
                written["k"] = w._cart_stiff
            if written.get("ft") is not w._tcp_ft:
                w._ctrl_ft[:] = w._tcp_ft
                written["ft"] = w._tcp_ft
            if written.get("jnt") is None:  # the joint gains of the joint modes off
                jnt = w._act_jnt
                w.model.actuator_gainprm[jnt, 0] = 0.0
                w.model.actuator_biasprm[jnt, 1:3] = 0.0
                written["jnt"] = True
            if written.get("trq") is not w._jnt_trq:
                w._jnt_trq_prm[:] = w._jnt_trq
                written["trq"] = w._jnt_trq
    else:
        m, ctrl, cart, jnt = w.model, w.data.ctrl, w._act_cart, w._act_jnt
        gain, bias = m.actuator_gainprm, m.actuator_biasprm
        w._written.clear()  # joint modes write over all of it
        w._latched = True
        w._inertia_new = True  # the Cartesian damping is rewritten on return
        bias[cart, 1] = 0.0
        bias[cart, 2] = 0.0
        ctrl[w._act_ft] = 0.0
        if w.mode == ArmMode.JOINT_POSITION:
            k = np.full(w._n, w.scene.controller.jnt_position_stiffness)
            dd = np.full(w._n, w.scene.controller.jnt_position_damping)
        else:
            k, dd = w._jnt_stiff, w._jnt_damp
        damp = normalized_damping(k, dd, w._m_diag)
        gain[jnt, 0] = k
        bias[jnt, 0] = w._jnt_trq
        bias[jnt, 1] = -k
        bias[jnt, 2] = -damp
        ctrl[jnt] = w._jnt_pos
    # f_dyn: Coriolis/centrifugal (gravity is compensated inside every step).
    np.subtract(w._bias_arm, w._gravcomp_arm, out=w._applied_arm)


def _write_cart_damping(w: SimWorld) -> None:
    """``-normalized_damping(K, d, diag Lambda)`` into the Cartesian actuators, the
    same operations in the same order; the factors of K and d are kept while those
    are the same objects (``-(a b)`` is ``(-a) b`` in IEEE arithmetic)."""
    written = w._written
    k, dr = w._cart_stiff, w._cart_damp
    if written.get("k_d") is not k:
        w._k_pos = np.maximum(k, 0.0)
        written["k_d"] = k
    if written.get("d") is not dr:
        w._neg_2d = np.negative(2.0 * dr)
        written["d"] = dr
    t = w._damp_work
    np.maximum(w._lam_diag, 0.0, out=t)
    np.multiply(w._k_pos, t, out=t)
    np.sqrt(t, out=t)
    np.multiply(w._neg_2d, t, out=w._cart_damp_prm)
