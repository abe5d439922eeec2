"""The scene's free-moving bodies as the simulator's truth reports them: each by name,
its pose and twist in the world frame. No I/O.

A body is free-moving when a joint other than the arm's moves it: the air-bed
target (slides and a hinge), a target in free flight (a free joint), a floating
base. :class:`FreeBodies` finds them in a compiled model, sets their start
velocity and reads their state; what a scenario makes of them (a funnel's
errors, an insertion depth) is the scenario's.

Twists are ``[vx, vy, vz, wx, wy, wz]``: the velocity of the body frame's
origin and the angular velocity, both in world coordinates
(``mj_objectVelocity`` with world orientation).
"""

from __future__ import annotations

import mujoco
import numpy as np

from drivers.base.types import F64, AttachedFrame, BodyTruth
from drivers.world.truth import pose as _pose

__all__ = ["FreeBodies", "body_twist"]

_OBJ_BODY = mujoco.mjtObj.mjOBJ_BODY
_OBJECT_VELOCITY = mujoco.mj_objectVelocity
#: MuJoCo's ``[w, v]`` as ``[v, w]``
_V_W = np.array([3, 4, 5, 0, 1, 2])


def body_twist(model: mujoco.MjModel, data: mujoco.MjData, body: int, work: F64) -> F64:
    """``[v, w]`` of body ``body``'s frame origin, world coordinates (a new array; needs
    the state's velocities, ``mj_comVel`` done); ``work`` is a 6-array it may overwrite."""
    _OBJECT_VELOCITY(model, data, _OBJ_BODY, body, work, 0)
    return work.take(_V_W)  # MuJoCo's order is [w, v]


def _local(pos: F64, quat: F64) -> F64:
    """4x4 of a position and a unit quaternion ``[w, x, y, z]`` (a body's or a site's in
    its parent)."""
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, np.asarray(quat, dtype=np.float64))
    return _pose(np.asarray(pos, dtype=np.float64), mat)


class FreeBodies:
    """The free-moving bodies of a model, by name (the order of the model's tree).

    Args:
        model, data: the compiled world.
        names: the bodies to report, each moved by a joint of its own.
    """

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData,
                 names: tuple[str, ...]) -> None:
        self.model, self.data = model, data
        self.ids: dict[str, int] = {}
        for name in names:
            bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
            if bid < 0:
                raise KeyError(f"no body {name!r} in the model")
            self.ids[name] = bid
        self._vel = np.zeros(6)
        self._mass = model.body_mass  # views into the model's and the state's buffers
        # per body: its id, position and row-major rotation (views, current every cycle)
        self._rows = tuple((name, bid, data.xpos[bid], data.xmat[bid])
                           for name, bid in self.ids.items())

    def report_mass(self, name: str, mass_kg: float) -> None:
        """Report ``name``'s mass as ``mass_kg`` in its truth, not its model body's: a
        rendered target's mock-up stands for the rendered body (``carrier.render_target``)."""
        self._mass = np.array(self._mass, copy=True)
        self._mass[self.ids[name]] = mass_kg

    def attached(self, sites: dict[str, int]) -> dict[str, AttachedFrame]:
        """The named frames (site ids by name) fixed on one of these bodies: each its
        body's name and its pose in that body's frame, from the model (the chain of
        bodies welded between them: no joint). A frame on no free body is left out."""
        m = self.model
        by_id = {bid: name for name, bid in self.ids.items()}
        out: dict[str, AttachedFrame] = {}
        for name, site in sites.items():
            if site < 0:
                continue
            offset = _local(m.site_pos[site], m.site_quat[site])
            bid = int(m.site_bodyid[site])
            while bid not in by_id and bid > 0 and m.body_jntnum[bid] == 0:
                offset = _local(m.body_pos[bid], m.body_quat[bid]) @ offset
                bid = int(m.body_parentid[bid])
            if bid in by_id:
                out[name] = AttachedFrame(by_id[bid], offset)
        return out

    def _free_dofs(self, name: str) -> int | None:
        """The first dof of the body's free joint (``None``: it has none)."""
        m = self.model
        bid = self.ids[name]
        for j in range(m.body_jntadr[bid], m.body_jntadr[bid] + m.body_jntnum[bid]):
            if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
                return int(m.jnt_dofadr[j])
        return None

    def set_free_twist(self, name: str, linear_mps: F64, angular_radps: F64) -> None:
        """Give the free body ``name`` a twist: its centre of mass' velocity and its angular
        velocity, both in the world frame (MuJoCo's free joint takes the angular velocity
        in the body frame: turned here)."""
        adr = self._free_dofs(name)
        if adr is None:
            raise ValueError(f"body {name!r} has no free joint")
        rot = self.data.xmat[self.ids[name]].reshape(3, 3)
        qvel = self.data.qvel
        qvel[adr:adr + 3] = linear_mps
        qvel[adr + 3:adr + 6] = rot.T @ np.asarray(angular_radps, dtype=np.float64)

    def pose(self, name: str) -> F64:
        """The body frame's 4x4 pose in the world (a new array)."""
        bid = self.ids[name]
        out = np.eye(4)
        out[:3, :3] = self.data.xmat[bid].reshape(3, 3)
        out[:3, 3] = self.data.xpos[bid]
        return out

    def twist(self, name: str) -> F64:
        """``[v, w]`` of the body frame's origin, world coordinates (a new array; needs
        the velocities of the state: ``mj_comVel`` done)."""
        return body_twist(self.model, self.data, self.ids[name], self._vel)

    def truth(self) -> dict[str, BodyTruth]:
        """Every body's state now (new arrays)."""
        m, d, work, mass = self.model, self.data, self._vel, self._mass
        out = {}
        for name, bid, xpos, xmat in self._rows:
            pose = _pose(xpos, xmat)
            _OBJECT_VELOCITY(m, d, _OBJ_BODY, bid, work, 0)
            out[name] = BodyTruth(pose, work.take(_V_W), float(mass[bid]))
        return out
