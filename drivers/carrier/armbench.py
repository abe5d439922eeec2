"""A rendered-target impact with both arms in one world (``carrier.model = "arm"``): the
carrier loop (:class:`~drivers.carrier.loop.CarrierLoop`) reads the carrier's F/T sensor
and commands a position-controlled arm through inverse kinematics, as ``servoJ`` takes
joint targets; the chaser's tool, held stiff, moves at the set speed. The world is any
:class:`~drivers.carrier.plant.CarrierPlant` (in process: :mod:`drivers.world.twoarm`; or
each arm behind its own emulator). No I/O here.

The trace is the point bench's (:class:`~drivers.carrier.bench.ImpactTrace`), so the
recording and its analysis are the same; the measured delay now includes the arm's
response.
"""

from __future__ import annotations

import math

import numpy as np

from drivers.base.types import F64
from drivers.carrier.bench import Impact, ImpactTrace
from drivers.carrier.body import cross3
from drivers.carrier.kinematics import ArmChain, IkError
from drivers.carrier.loop import CarrierLoop
from drivers.carrier.plant import ArmLayout, CarrierPlant
from drivers.description.impact import damping_ratio_for
from drivers.description.scene import Scene, inertia_tensor

__all__ = ["ArmServo", "run_arm_impact"]


class ArmServo:
    """The carrier arm as the loop's :class:`~drivers.carrier.loop.Flange`: a set-point of
    the mock-up's centre becomes joint targets (inverse kinematics from the last target;
    joint velocities by least squares), and the mock-up's state is read from the arm's
    measured joints (forward kinematics; its acceleration the change of its velocity over
    the last cycle)."""

    def __init__(self, chain: ArmChain, q0: F64, centre_m: F64, cycle_s: float) -> None:
        self.chain, self.centre, self.cycle_s = chain, np.asarray(centre_m), cycle_s
        self.q_target = np.array(q0, dtype=np.float64)
        self.qd_target = np.zeros_like(self.q_target)
        self.held = False
        self.failed: str | None = None
        self._pos = self.centre.copy()
        self._rot = np.eye(3)
        self._twist = np.zeros(6)
        self._acc = np.zeros(3)
        self.angular_acc = np.zeros(3)
        """The mock-up's angular acceleration over the last cycle (world)."""
        self._q = self.q_target.copy()
        self.measure(self.q_target, self.qd_target, first=True)

    def measure(self, q: F64, qd: F64, *, first: bool = False) -> None:
        """The arm's joints at a cycle's end."""
        pose, jac = self.chain.jacobian(q)
        twist = jac @ qd
        acc = np.zeros(6) if first else (twist - self._twist) / self.cycle_s
        self._acc, self.angular_acc = acc[:3], acc[3:]
        self._pos, self._rot, self._twist, self._q = pose[:3, 3], pose[:3, :3], twist, q

    def send(self, pos: F64, vel: F64, rot: F64, omega: F64) -> None:
        if self.held:
            return
        target = np.eye(4)
        target[:3, :3] = rot
        target[:3, 3] = self.centre + pos
        try:
            q = self.chain.solve_ik(target, self.q_target)
        except IkError as exc:
            self.failed = f"carrier inverse kinematics: {exc}"
            return
        self.qd_target = self.chain.joint_velocity(q, np.concatenate((vel, omega)))
        self.q_target = q

    def hold(self, t_s: float) -> None:
        self.held = True
        self.q_target = self._q.copy()
        self.qd_target = np.zeros_like(self.q_target)

    def at(self, t_s: float) -> tuple[F64, F64, F64, F64]:
        return self._pos - self.centre, self._rot, self._twist, self._acc

    def torque_inertia(self, inertia: F64) -> F64:
        """The torque a mock-up of ``inertia`` (body frame, about its centre) takes to turn
        as the arm turns it now (``I a + w x I w``, world): what its sensor reads besides
        the contact's (the loop compensates the force's share itself)."""
        i_w = self._rot @ inertia @ self._rot.T
        w = self._twist[3:]
        return np.asarray(i_w @ self.angular_acc + np.cross(w, i_w @ w))


def run_arm_impact(scene: Scene, impact: Impact, layout: ArmLayout,
                   plant: CarrierPlant) -> ImpactTrace:
    """Run one impact on ``plant`` laid out as ``layout`` (the trace as
    :func:`drivers.carrier.bench.run_impact`'s)."""
    cs = scene.carrier
    tg = scene.target
    inertia = inertia_tensor(tg.mass, tg.size, tg.inertia)
    half = 0.5 * tg.size[0]
    lever = cross3(np.array([-half, impact.offset_m, 0.0]), np.array([1.0, 0.0, 0.0]))
    m_eff = 1.0 / (1.0 / tg.mass + float(lever @ np.linalg.solve(inertia, lever)))
    k = scene.contact.stiffness
    c = 2.0 * damping_ratio_for(scene.contact.restitution) * math.sqrt(k * m_eff)
    trace = ImpactTrace(effective_mass_kg=m_eff, stiffness_npm=k, damping_nspm=c)
    speed = np.array([impact.speed_mps, 0.0, 0.0])
    tool_v = speed.copy()
    servo = ArmServo(layout.carrier, layout.carrier_q0, layout.centre_m, cs.cycle_s)
    loop = CarrierLoop(scene, inertia, speed, flange=servo)
    mock_inertia = inertia_tensor(cs.mockup_mass_kg, tg.size, None)
    chaser = layout.chaser
    chaser_pose = chaser.pose(layout.chaser_q0)
    chaser_q = layout.chaser_q0.copy()
    ft_period = 1.0 / scene.ft_sensor.rate
    tip = chaser_pose[:3, 3] - layout.centre_m
    state = plant.start()
    end_s = impact.duration_s
    stop_at: float | None = None
    n = 0
    try:
        while True:
            t = n * cs.cycle_s
            if t > end_s + 1e-12 or (stop_at is not None and t >= stop_at - 1e-12):
                break
            servo.measure(state.carrier_q, state.carrier_qd)
            spin = servo.torque_inertia(mock_inertia)
            fresh = [(ts, np.concatenate((w[:3], w[3:] + spin)), servo.at(ts)[2])
                     for ts, w in state.samples
                     if impact.ft_stale_at_s is None or ts < impact.ft_stale_at_s]
            alive = impact.link_lost_at_s is None or t < impact.link_lost_at_s
            if state.lost is not None:
                loop.stop(t, state.lost)
            loop.cycle(t, fresh, ft_period, link_alive=alive)
            if servo.failed is not None and loop.hold is None:
                loop.stop(t, servo.failed)
            if loop.hold is not None and stop_at is None:
                tool_v = np.zeros(3)  # the chaser stops
                stop_at = t + 10 * cs.cycle_s
            trace.cycle_t_s.append(t)
            trace.cycle.append(loop.values(tip, tool_v))
            # the chaser's tool along its line: its joints to the next cycle's pose
            target = chaser_pose.copy()
            target[:3, 3] = target[:3, 3] + tool_v * cs.cycle_s
            q_next = chaser.solve_ik(target, chaser_q)
            qd = (q_next - chaser_q) / cs.cycle_s
            state = plant.step(servo.q_target, servo.qd_target, q_next, qd)
            chaser_pose, chaser_q = target, q_next
            tip = tip + tool_v * cs.cycle_s
            for row in state.fine:
                ft, f = row[0], row[2]
                if trace.contact(ft, f) and stop_at is None:
                    stop_at = ft + impact.after_s
                trace.fine_t_s.append(ft)
                trace.fine.append(tuple(row[1:]))
            n += 1
    finally:
        plant.close()
    trace.hold = loop.hold
    return trace
