"""The arm's floating base (``base.mode`` not ``"fixed"``): the chaser spacecraft. No I/O.

:class:`FloatingBase` turns the world's poses into the arm's base frame (the
frame the controllers work in, as on a real servicer), keeps the frame of the
superposed wrench on the TCF, and applies the base's own control once per
control cycle (held for the cycle):

* ``free_floating``: nothing;
* ``attitude_held``: ``tau = -kp theta - kd omega`` with ``theta`` the rotation vector
  from the start attitude, each body-axis component clipped to ``torque_limit``;
* ``pose_held``: the same, plus ``f = -kp (p - p0) - kd v`` on the centre of mass, each
  body-axis component clipped to ``force_limit``.

The wrenches act on the base's centre of mass through ``xfrc_applied`` (world frame).
"""

from __future__ import annotations

import mujoco
import numpy as np

from drivers.base.types import F64
from drivers.description.scene import BaseSettings
from drivers.world import mjcf
from drivers.world.bodies import body_twist

__all__ = ["FloatingBase", "base_wrench"]


def base_wrench(settings: BaseSettings, rot: F64, pos: F64, twist: F64, rot0: F64,
                pos0: F64) -> F64:
    """The base controller's wrench ``[f, tau]`` in the world frame at the centre of mass,
    from the base's attitude ``rot``, position ``pos`` and twist ``[v, w]`` (world), and
    the attitude and position it holds. Pure."""
    out = np.zeros(6)
    if settings.mode == "free_floating":
        return out
    err = np.zeros(3)
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(rot @ rot0.T).ravel())
    mujoco.mju_quat2Vel(err, quat, 1.0)  # the rotation vector of the attitude error
    tau = -settings.attitude_kp * err - settings.attitude_kd * twist[3:]
    tau_body = np.clip(rot.T @ tau, -settings.torque_limit, settings.torque_limit)
    out[3:] = rot @ tau_body
    if settings.mode == "pose_held":
        f = -settings.position_kp * (pos - pos0) - settings.position_kd * twist[:3]
        f_body = np.clip(rot.T @ f, -settings.force_limit, settings.force_limit)
        out[:3] = rot @ f_body
    return out


class FloatingBase:
    """The chaser body of a world whose scene has a floating base."""

    def __init__(self, settings: BaseSettings, model: mujoco.MjModel,
                 data: mujoco.MjData) -> None:
        self.settings = settings
        self.model, self.data = model, data
        self.body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, mjcf.BASE_BODY)
        self.link0 = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "link0")
        ft_ref = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, mjcf.FT_REF_SITE)
        model.site_sameframe[ft_ref] = 0  # turned at run time: not its body's frame
        self._ft_ref_quat = model.site_quat[ft_ref]
        self._xfrc = data.xfrc_applied[self.body]
        self._vel = np.zeros(6)
        self._quat = np.zeros(4)
        self._rot0, self._pos0 = np.eye(3), np.zeros(3)

    def hold(self) -> None:
        """Hold the attitude and position the base has now (the world calls it at t = 0;
        needs the state's kinematics)."""
        d = self.data
        self._rot0 = d.xmat[self.body].reshape(3, 3).copy()
        self._pos0 = d.xipos[self.body].copy()

    def arm_base_pose(self) -> F64:
        """The arm's base frame (link0) in the world, 4x4 (a new array)."""
        out = np.eye(4)
        out[:3, :3] = self.data.xmat[self.link0].reshape(3, 3)
        out[:3, 3] = self.data.xpos[self.link0]
        return out

    def in_base(self, pos: F64, mat9: F64) -> F64:
        """A world frame (position, row-major rotation) in the arm's base frame, 4x4."""
        r = self.data.xmat[self.link0].reshape(3, 3)
        out = np.eye(4)
        out[:3, :3] = r.T @ mat9.reshape(3, 3)
        out[:3, 3] = r.T @ (pos - self.data.xpos[self.link0])
        return out

    def cycle(self, tcp_in_base: F64) -> None:
        """Before a control cycle's physics: the wrench's frame onto the TCF, the base
        controller's wrench applied for the cycle (needs the state's velocities)."""
        mujoco.mju_mat2Quat(self._quat, np.ascontiguousarray(tcp_in_base[:3, :3]).ravel())
        self._ft_ref_quat[:] = self._quat
        d = self.data
        twist = body_twist(self.model, d, self.body, self._vel)  # its frame is its centre
        self._xfrc[:] = base_wrench(self.settings, d.xmat[self.body].reshape(3, 3),
                                    d.xipos[self.body], twist, self._rot0, self._pos0)
