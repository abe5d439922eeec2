"""The free target rendered by a carrier in the simulator's world (``carrier.render_target``):
what the chaser touches is the carrier's mock-up, a body of ``carrier.mockup_mass_kg`` with
the target's shape and funnel, held by a servo (a soft weld to a kinematic flange,
``solref`` time constant ``1 / (2 pi carrier.servo_bandwidth_hz)``, critically damped) to
the pose the carrier loop (:class:`~drivers.carrier.loop.CarrierLoop`, its interpolator)
renders from the contact's wrench; the target's mass and inertia are the rendered body's.

Each world cycle the mock-up's sensor reads the contact's wrench on it (the funnel
contacts' force on the tool, reversed and moved to the mock-up's centre; the mock-up's own
weight and inertia taken as compensated), with ``ft_sensor.noise_std``; the reading
reaches the loop ``ft_sensor.delay_s`` later (whole world cycles). Every
``carrier.cycle_s`` (a whole number of world cycles) the loop integrates the rendered
body and sends its set-point; the flange moves to the interpolator's pose at the end of
each world cycle. The rendered body starts at the target's start pose with its drift and
tumble. A hold (a limit, a stale sensor) keeps the mock-up where it is: :attr:`hold`.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from drivers.base.types import F64
from drivers.carrier.loop import CarrierLoop, Hold
from drivers.description.scene import Scene
from drivers.errors import ConfigError

__all__ = ["FLANGE_BODY", "RenderedTarget", "flange_xml"]

#: The kinematic body the mock-up is welded to.
FLANGE_BODY = "carrier_flange"


def flange_xml(scene: Scene, pos: str, quat: str, target: str) -> tuple[str, str]:
    """The flange's body and the weld (MJCF, for :mod:`drivers.world.mjcf`)."""
    tc = max(1.0 / (2.0 * math.pi * scene.carrier.servo_bandwidth_hz),
             2.0 * scene.physics.timestep)
    return (f'<body name="{FLANGE_BODY}" mocap="true" pos="{pos}" quat="{quat}"/>',
            f'<equality><weld body1="{target}" body2="{FLANGE_BODY}" '
            f'solref="{tc:.9g} 1"/></equality>')


class RenderedTarget:
    """The carrier loop on the world's mock-up (see the module)."""

    def __init__(self, scene: Scene, model: mujoco.MjModel, data: mujoco.MjData,
                 target_body: int, rng: np.random.Generator) -> None:
        cs = scene.carrier
        if scene.target.support != "free":
            raise ConfigError(scene.name, "carrier.render_target", "renders a free target: "
                              f"needs target.support = 'free', not {scene.target.support!r}")
        cycle = scene.fri.cycle
        every = cs.cycle_s / cycle
        if abs(every - round(every)) > 1e-9 or round(every) < 1:
            raise ConfigError(scene.name, "carrier.cycle_s", f"{cs.cycle_s:g} s is not a "
                              f"whole number of world cycles (fri.cycle {cycle:g} s)")
        self.every, self.cycle_s = round(every), cycle
        self.delay = round(scene.ft_sensor.delay_s / cycle)
        self._d, self._body = data, target_body
        self._mocap = int(model.body_mocapid[mujoco.mj_name2id(
            model, mujoco.mjtObj.mjOBJ_BODY, FLANGE_BODY)])
        self.p0 = data.xpos[target_body].copy()
        self.r0 = data.xmat[target_body].reshape(3, 3).copy()
        tg = scene.target
        inertia = self.r0 @ tg.inertia_matrix() @ self.r0.T
        loop_scene = scene.model_copy(update={"carrier": cs.model_copy(
            update={"mockup_mass_kg": 0.0})})
        self.loop = CarrierLoop(loop_scene, inertia, np.zeros(3), energy_check=False)
        body = self.loop.body
        body.velocity_mps = np.asarray(tg.drift_mps, dtype=np.float64).copy()
        body.momentum = inertia @ np.asarray(tg.tumble_radps, dtype=np.float64)
        self._rng = rng
        self._noise = np.array(scene.ft_sensor.noise_std)[[0, 0, 0, 1, 1, 1]]
        self._pending: list[tuple[int, float, F64]] = []
        self._period = cycle  # one sample a world cycle
        self._quat = np.zeros(4)

    @property
    def hold(self) -> Hold | None:
        """Why and when the carrier held, if it did."""
        return self.loop.hold

    def cycle(self, k: int, tool_wrench_tcp: F64, tcp_pos: F64, tcp_rot: F64) -> None:
        """After world cycle ``k``: the sensor's sample, the loop when due, the flange's
        next pose. ``tool_wrench_tcp``: the contact's wrench on the tool at the TCP, TCF."""
        t = (k + 1) * self.cycle_s
        d = self._d
        force = -(tcp_rot @ tool_wrench_tcp[:3])
        torque = -(tcp_rot @ tool_wrench_tcp[3:]) + np.cross(tcp_pos - d.xpos[self._body], force)
        reading = np.concatenate((force, torque)) + self._noise * self._rng.standard_normal(6)
        self._pending.append((k + 1 + self.delay, t, reading))
        if (k + 1) % self.every == 0:
            servo = self.loop.servo  # the mock-up's twist at each sample's time
            due = [(ts, w, servo.at(ts)[2]) for kk, ts, w in self._pending if kk <= k + 1]
            self._pending = [p for p in self._pending if p[0] > k + 1]
            self.loop.cycle(t, due, self._period)
        pos, rot, _, _ = self.loop.servo.at(t + self.cycle_s)
        d.mocap_pos[self._mocap] = self.p0 + pos
        mujoco.mju_mat2Quat(self._quat, np.ascontiguousarray(rot @ self.r0).ravel())
        d.mocap_quat[self._mocap] = self._quat
