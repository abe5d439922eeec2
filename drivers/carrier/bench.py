"""A simulated impact on a rendered target: the chaser's tool, held stiff (its motion
imposed), meets the mock-up on a carrier robot that renders the scene's free-floating
target from its F/T sensor (:class:`~drivers.carrier.loop.CarrierLoop`). No I/O.

The physics between the tool and the mock-up runs at a fine step
(``physics.timestep / 10``): a unilateral spring-damper of the scene's
``contact.stiffness`` whose damping makes a free impact rebound with
``contact.restitution`` (for the effective mass at the contact point), between the
tool's tip (a point moving at the set speed) and the mock-up's face (the target's
``-x`` face, ``target.size``). The carrier's F/T sensor samples at ``ft_sensor.rate``,
its sample reaches the loop ``ft_sensor.delay_s`` later with its noise; the flange
follows the loop's set-points (:class:`~drivers.carrier.loop.Servo`).

``render = False`` is the same impact on the ideal free body (no carrier: the contact
force acts on the body at the fine step), whose restitution is the target's true one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from drivers.base.types import F64
from drivers.carrier.body import FreeBody, cross3
from drivers.carrier.loop import CarrierLoop, Hold, cycle_values
from drivers.description.impact import damping_ratio_for
from drivers.description.scene import Scene, inertia_tensor
from drivers.errors import ConfigError

__all__ = ["BENCH_SUBSTEPS", "Impact", "ImpactTrace", "run_impact"]

#: Fine physics steps per scene physics step.
BENCH_SUBSTEPS = 10


@dataclass(frozen=True)
class Impact:
    """One impact: how the chaser's tool meets the mock-up, and faults to inject."""

    speed_mps: float = 0.1
    """The tool's speed along the world x axis, into the mock-up's -x face."""
    gap_m: float = 0.002
    """Tool tip to face at the start."""
    offset_m: float = 0.0
    """Where on the face the tip meets it, along the target's y axis from the centre."""
    after_s: float = 0.1
    """How long the run goes on once the contact has ended."""
    duration_s: float = 1.0
    """The longest run."""
    render: bool = True
    """False: the ideal free body, no carrier."""
    ft_stale_at_s: float | None = None
    """Fault: the carrier's F/T sensor delivers nothing from this time on."""
    link_lost_at_s: float | None = None
    """Fault: the carrier's link stops answering from this time on."""


@dataclass
class ImpactTrace:
    """What a run produced: a fine trace of the contact, a per-cycle trace of the loop."""

    fine_t_s: list[float] = field(default_factory=list)
    fine: list[tuple[float, ...]] = field(default_factory=list)
    """Per fine step: penetration, normal force, the mock-up contact point's normal
    velocity, the tool tip's x."""
    cycle_t_s: list[float] = field(default_factory=list)
    cycle: list[tuple[float, ...]] = field(default_factory=list)
    """Per carrier cycle (the ideal body's too, with the contact's wrench at that
    instant as both wrenches): see :data:`CYCLE_FIELDS`."""
    hold: Hold | None = None
    effective_mass_kg: float = 0.0
    stiffness_npm: float = 0.0
    damping_nspm: float = 0.0
    contact_start_s: float | None = None
    contact_end_s: float | None = None

    def contact(self, t_s: float, force_n: float) -> bool:
        """Note the contact's normal force at ``t_s``: its first start, and its end after
        the last start; True at the step it ends."""
        if force_n > 0.0:
            if self.contact_start_s is None:
                self.contact_start_s = t_s
            self.contact_end_s = None
        elif self.contact_start_s is not None and self.contact_end_s is None:
            self.contact_end_s = t_s
            return True
        return False


#: Per-cycle values, in order: the rendered body's position (3), rotation vector (3),
#: twist (6), the flange's position (3), the measured and the applied wrench (6 + 6),
#: the closing speed at the contact point, the observer's generated energy, the
#: controller's dissipated energy, the rendered kinetic energy in the tool's frame.
CYCLE_FIELDS = ("position", "rotvec", "twist", "flange", "wrench_measured", "wrench_applied",
                "closing_mps", "generated_j", "dissipated_j", "energy_j")


def _fine_step(scene: Scene) -> tuple[float, int, int, int]:
    """The fine step and the carrier cycle, F/T period and F/T delay in fine steps."""
    h = scene.physics.timestep / BENCH_SUBSTEPS
    out: list[int] = []
    for name, value in (("carrier.cycle_s", scene.carrier.cycle_s),
                        ("ft_sensor.rate", 1.0 / scene.ft_sensor.rate)):
        n = value / h
        if abs(n - round(n)) > 1e-6 or round(n) < 1:
            raise ConfigError(scene.name, name, f"{value:g} s is not a multiple of "
                              f"physics.timestep / {BENCH_SUBSTEPS} = {h:g} s")
        out.append(round(n))
    return h, out[0], out[1], round(scene.ft_sensor.delay_s / h)


def run_impact(scene: Scene, impact: Impact, seed: int = 0) -> ImpactTrace:
    """Run one impact; the trace ends ``after_s`` past the contact, at ``duration_s``, or
    a few cycles after the carrier held."""
    h, n_cycle, n_ft, n_delay = _fine_step(scene)
    rng = np.random.default_rng(seed)
    half = 0.5 * scene.target.size[0]
    inertia = inertia_tensor(scene.target.mass, scene.target.size, scene.target.inertia)
    normal = np.array([1.0, 0.0, 0.0])  # into the mock-up from its -x face (body frame)
    face = np.array([-half, 0.0, 0.0])
    tip0 = np.array([-half - impact.gap_m, impact.offset_m, 0.0])
    lever = np.array([-half, impact.offset_m, 0.0])
    arm = cross3(lever, normal)
    m_eff = 1.0 / (1.0 / scene.target.mass + float(arm @ np.linalg.solve(inertia, arm)))
    k = scene.contact.stiffness
    c = 2.0 * damping_ratio_for(scene.contact.restitution) * math.sqrt(k * m_eff)
    trace = ImpactTrace(effective_mass_kg=m_eff, stiffness_npm=k, damping_nspm=c)
    speed = np.array([impact.speed_mps, 0.0, 0.0])
    tool_v = speed.copy()
    tip = tip0.copy()
    loop = CarrierLoop(scene, inertia, speed) if impact.render else None
    servo = loop.servo if loop is not None else None
    ideal = None if impact.render else _IdealBody(scene.target.mass, inertia)
    noise = np.array(scene.ft_sensor.noise_std)[[0, 0, 0, 1, 1, 1]]
    g_lab = np.array([0.0, 0.0, -scene.carrier.lab_gravity_mps2])
    mock = scene.carrier.mockup_mass_kg
    pending: list[tuple[int, float, F64, F64]] = []  # (due step, sample time, wrench, twist)
    end_step = round(impact.duration_s / h)
    stop_at: int | None = None
    i = 0
    while i <= end_step and (stop_at is None or i < stop_at):
        t = i * h
        if servo is not None:
            pos, rot, twist, accel = servo.at(t)
        else:
            assert ideal is not None
            pos, rot, twist, accel = ideal.pos, ideal.rot, ideal.twist(), np.zeros(3)
        if loop is not None and i % n_cycle == 0:
            fresh = [(ts, w, tw) for due, ts, w, tw in pending if due <= i]
            pending = [p for p in pending if p[0] > i]
            alive = impact.link_lost_at_s is None or t < impact.link_lost_at_s
            loop.cycle(t, fresh, h * n_ft, link_alive=alive)
            if loop.hold is not None and stop_at is None:
                tool_v = np.zeros(3)  # the chaser stops
                stop_at = i + 10 * n_cycle
            trace.cycle_t_s.append(t)
            trace.cycle.append(loop.values(tip, tool_v))
        # the contact
        n_w = rot @ normal
        r = tip - pos
        depth = float((tip - (pos + rot @ face)) @ n_w)
        v_pt = twist[:3] + cross3(twist[3:], r)
        closing = float((tool_v - v_pt) @ n_w)
        f = max(0.0, k * depth + c * closing) if depth > 0.0 else 0.0
        force = f * n_w
        torque = cross3(r, force)
        if trace.contact(t, f) and stop_at is None:
            stop_at = i + round(impact.after_s / h)
        trace.fine_t_s.append(t)
        trace.fine.append((depth, f, float(v_pt @ n_w), float(tip[0])))
        if loop is not None and i % n_ft == 0 and (
                impact.ft_stale_at_s is None or t < impact.ft_stale_at_s):
            reading = np.concatenate((force + mock * (g_lab - accel), torque))
            reading = reading + noise * rng.standard_normal(6)
            pending.append((i + n_delay, t, reading, twist.copy()))
        if ideal is not None:
            if i % n_cycle == 0:
                trace.cycle_t_s.append(t)
                trace.cycle.append(ideal.values(tip, tool_v, force, torque))
            ideal.step(force, torque, h)
        tip = tip + tool_v * h
        i += 1
    if loop is not None:
        trace.hold = loop.hold
    return trace


class _IdealBody:
    """The target as a free body under the contact force itself (no carrier)."""

    def __init__(self, mass: float, inertia: F64) -> None:
        self.body = FreeBody(mass, inertia, np.zeros(3), np.eye(3), np.zeros(3), np.zeros(3))

    @property
    def pos(self) -> F64:
        return self.body.position_m

    @property
    def rot(self) -> F64:
        return self.body.rotation

    def twist(self) -> F64:
        return np.concatenate((self.body.velocity_mps, self.body.angular_radps))

    def step(self, force: F64, torque: F64, h: float) -> None:
        self.body.step(force, torque, h)

    def values(self, tip: F64, tool_v: F64, force: F64, torque: F64) -> tuple[float, ...]:
        wrench = np.concatenate((force, torque))
        return cycle_values(self.body, self.body.position_m, tip, tool_v, wrench, wrench,
                            0.0, 0.0)

