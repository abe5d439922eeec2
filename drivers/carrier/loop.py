"""The micro-gravity emulator's loop, one carrier cycle at a time, and the carrier's
position servo. No I/O.

Each cycle :meth:`CarrierLoop.cycle`:

1. takes the F/T samples that reached it and compensates the mock-up's weight and
   inertia (the flange's acceleration at each sample's time, from the servo's own
   interpolation); a sample older than ``carrier.ft_stale_s``, a force above
   ``carrier.force_limit_n`` or a link that stopped answering holds the carrier;
2. delays the wrench by ``carrier.extra_delay_cycles`` and compensates it
   (:mod:`drivers.carrier.passivity`);
3. integrates the rendered free body over the cycle (:mod:`drivers.carrier.body`);
4. sends the body's pose (plus the virtual compliance's offset) and twist as the next
   set-point, unless it leaves the workspace box, exceeds the speed limit, or the
   rendered target left the contact with more energy (in the tool's frame) than it
   came with: a passive contact cannot give it any, the loop did (the loop is beyond
   its critical delay). Any of these holds the carrier where it is.

:class:`Servo` is the carrier's interpolator: the set-point sent in cycle ``k`` is
reached at the end of cycle ``k + 1 + response_cycles``, along a cubic (Hermite) path
through the set-points' poses and twists.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from drivers.base.types import F64
from drivers.carrier.body import FreeBody, cross3, rotation_exp, rotation_log
from drivers.carrier.passivity import PassivityController, VirtualCompliance
from drivers.description.scene import Scene

__all__ = ["CarrierLoop", "Flange", "Hold", "Servo", "cycle_values"]

#: Below this kinetic energy in the tool's frame [J] the energy check does not judge (a
#: target at rest relative to the tool; sensor noise gives a free body far less).
ENERGY_FLOOR_J = 1e-6


@dataclass(frozen=True)
class Hold:
    """Why and when a device stopped the run."""

    t_s: float
    device: str
    cause: str


class Flange(Protocol):
    """What the loop commands and reads of the carrier: :class:`Servo` (the interpolator)
    or an arm (:class:`drivers.carrier.armbench.ArmServo`)."""

    def send(self, pos: F64, vel: F64, rot: F64, omega: F64) -> None:
        """The next set-point of the mock-up's centre (the loop's frame)."""

    def hold(self, t_s: float) -> None:
        """Stop where the flange is at ``t_s`` and stay there."""

    def at(self, t_s: float) -> tuple[F64, F64, F64, F64]:
        """The mock-up's position, rotation, twist and acceleration at ``t_s``."""


class Servo:
    """The carrier's interpolator (see the module)."""

    def __init__(self, cycle_s: float, response_cycles: int, pos: F64, rot: F64) -> None:
        self.cycle_s, self.response = cycle_s, response_cycles
        zero = np.zeros(3)
        self._points: list[tuple[F64, F64, F64, F64]] = [(pos, zero, rot, zero)]
        self._segments: dict[int, F64] = {}
        self._held: tuple[float, F64, F64] | None = None

    def send(self, pos: F64, vel: F64, rot: F64, omega: F64) -> None:
        """The next set-point (world frame)."""
        self._points.append((pos.copy(), vel.copy(), rot.copy(), omega.copy()))

    def hold(self, t_s: float) -> None:
        """Stop where the flange is at ``t_s`` and stay there."""
        pos, rot, _, _ = self.at(t_s)
        self._held = (t_s, pos, rot)

    def at(self, t_s: float) -> tuple[F64, F64, F64, F64]:
        """The flange's position, rotation, twist and acceleration at ``t_s``."""
        if self._held is not None and t_s >= self._held[0]:
            return self._held[1], self._held[2], np.zeros(6), np.zeros(3)
        u = t_s / self.cycle_s - self.response
        j = math.floor(u + 1e-9)
        s = max(0.0, u - j)
        if j < 0:
            p, _, r, _ = self._points[0]
            return p, r, np.zeros(6), np.zeros(3)
        if j + 1 >= len(self._points):  # no newer set-point: stand at the last
            p, v, r, w = self._points[-1]
            if j + 1 == len(self._points) and s < 1e-9:  # it is being reached now
                return p, r, np.concatenate((v, w)), np.zeros(3)
            return p, r, np.zeros(6), np.zeros(3)
        p0, v0, r0, w0 = self._points[j]
        p1, v1, r1, w1 = self._points[j + 1]
        t = self.cycle_s
        s2, s3 = s * s, s * s * s
        h10, h01, h11 = s3 - 2 * s2 + s, -2 * s3 + 3 * s2, s3 - s2
        d00, d10, d01, d11 = 6 * s2 - 6 * s, 3 * s2 - 4 * s + 1, -6 * s2 + 6 * s, 3 * s2 - 2 * s
        a00, a10, a01, a11 = 12 * s - 6, 6 * s - 4, -12 * s + 6, 6 * s - 2
        pos = p0 + h10 * t * v0 + h01 * (p1 - p0) + h11 * t * v1
        vel = (d00 * p0 + d10 * t * v0 + d01 * p1 + d11 * t * v1) / t
        acc = (a00 * p0 + a10 * t * v0 + a01 * p1 + a11 * t * v1) / (t * t)
        delta = self._segments.get(j)
        if delta is None:
            delta = self._segments[j] = rotation_log(r1 @ r0.T)
        theta = h10 * t * w0 + h01 * delta + h11 * t * w1
        omega = (d10 * t * w0 + d01 * delta + d11 * t * w1) / t
        return pos, rotation_exp(theta) @ r0, np.concatenate((vel, omega)), acc


def cycle_values(body: FreeBody, flange: F64, tip: F64, tool_v: F64, measured: F64,
                 applied: F64, generated_j: float, dissipated_j: float) -> tuple[float, ...]:
    """One cycle's record (:data:`drivers.carrier.bench.CYCLE_FIELDS`)."""
    w = body.angular_radps
    n_w = body.rotation[:, 0]
    v_pt = body.velocity_mps + cross3(w, tip - body.position_m)
    closing = float((tool_v - v_pt) @ n_w)
    return (*body.position_m, *rotation_log(body.rotation), *body.velocity_mps, *w,
            *flange, *measured, *applied, closing, generated_j, dissipated_j,
            body.kinetic_energy_j(tool_v))


class CarrierLoop:
    """The emulator's loop for the scene's target (start: at the origin, at rest).

    Args:
        scene: the target's mass, size and inertia and the ``[carrier]`` settings.
        inertia: the target's inertia tensor (body frame).
        tool_velocity: the chaser tool's velocity (the frame the energy check uses).
        flange: the carrier (default: :class:`Servo`, the interpolator).
        energy_check: hold when a contact leaves the target with more energy than it came
            with (an impact's check; off where the chaser's tool is not held at one speed).
    """

    def __init__(self, scene: Scene, inertia: F64, tool_velocity: F64,
                 flange: Flange | None = None, *, energy_check: bool = True) -> None:
        cs = self.settings = scene.carrier
        self.cycle_s = cs.cycle_s
        self.body = FreeBody(scene.target.mass, inertia, np.zeros(3), np.eye(3),
                             np.zeros(3), np.zeros(3))
        self.servo: Flange = flange if flange is not None else Servo(
            cs.cycle_s, cs.response_cycles, np.zeros(3), np.eye(3))
        self._line: deque[F64] = deque(maxlen=cs.extra_delay_cycles + 1)
        self.passivity = PassivityController(active=cs.compensation == "passivity")
        k_v = cs.compliance_stiffness_npm or 2.0 * scene.contact.stiffness
        c_v = 2.0 * math.sqrt(k_v * scene.target.mass)  # critical with the rendered mass
        self.compliance = (VirtualCompliance(k_v, c_v) if cs.compensation == "compliance"
                           else None)
        self._g = np.array([0.0, 0.0, -cs.lab_gravity_mps2])
        self._energy_check = energy_check
        self._tool_v = np.asarray(tool_velocity, dtype=np.float64)
        self._frame = np.concatenate((self._tool_v, np.zeros(3)))
        self._ke_start = self.body.kinetic_energy_j(self._tool_v)
        self._last_sample_s = 0.0
        self.measured = np.zeros(6)
        self.applied = np.zeros(6)
        self.hold: Hold | None = None
        self._t = 0.0

    def _stop(self, t_s: float, cause: str) -> None:
        self.hold = Hold(t_s, "carrier", cause)
        self.servo.hold(t_s)

    def stop(self, t_s: float, cause: str) -> None:
        """Hold the carrier for a cause found outside the loop (its link, its arm)."""
        if self.hold is None:
            self._stop(t_s, cause)

    def cycle(self, t_s: float, samples: list[tuple[float, F64, F64]], ft_period_s: float,
              *, link_alive: bool = True) -> None:
        """One cycle at ``t_s`` with the F/T samples that arrived since the last
        (``(sample time, reading, the flange's twist then)``)."""
        self._t = t_s
        if self.hold is not None:
            return
        cs = self.settings
        if not link_alive:
            self._stop(t_s, "carrier link lost: no answer to the set-point of this cycle")
            return
        mock = cs.mockup_mass_kg
        for ts, reading, twist in samples:
            comp = reading.copy()
            comp[:3] -= mock * (self._g - self.servo.at(ts)[3])
            self.passivity.physical(comp, twist - self._frame, ft_period_s)
            self.measured, self._last_sample_s = comp, ts
        age = t_s - self._last_sample_s
        if age > cs.ft_stale_s:
            self._stop(t_s, f"carrier F/T stale: newest sample {age * 1e3:.1f} ms old "
                       f"(carrier.ft_stale_s {cs.ft_stale_s * 1e3:g} ms)")
            return
        force = float(np.linalg.norm(self.measured[:3]))
        if force > cs.force_limit_n:
            self._stop(t_s, f"carrier force {force:.1f} N above carrier.force_limit_n "
                       f"{cs.force_limit_n:g} N")
            return
        self._line.append(self.measured)
        used = self._line[0] if len(self._line) == self._line.maxlen else np.zeros(6)
        body = self.body
        twist = np.concatenate((body.velocity_mps, body.angular_radps)) - self._frame
        self.applied = self.passivity.control(used, twist, self._energy(), self.cycle_s,
                                              body.mass_matrix)
        body.step(self.applied[:3], self.applied[3:], self.cycle_s, cs.integrator)
        self.passivity.observe(self._energy())
        pos, vel = body.position_m, body.velocity_mps
        if self.compliance is not None:
            self.compliance.update(used[:3], self.cycle_s)
            pos, vel = pos + self.compliance.offset_m, vel + self.compliance.rate_mps
        self._check(t_s, pos, vel)
        if self.hold is None:
            self.servo.send(pos, vel, body.rotation, body.angular_radps)

    def _energy(self) -> float:
        """The rendered body's kinetic energy in the chaser's frame."""
        return self.body.kinetic_energy_j(self._tool_v)

    def _check(self, t_s: float, pos: F64, vel: F64) -> None:
        cs = self.settings
        for axis, value, limit in zip("xyz", pos, cs.workspace_m, strict=True):
            if abs(value) > limit:
                self._stop(t_s, f"carrier workspace: set-point {axis} = {value:+.3f} m outside "
                           f"carrier.workspace_m +-{limit:g} m")
                return
        speed = float(np.linalg.norm(vel))
        if speed > cs.speed_limit_mps:
            self._stop(t_s, f"carrier speed {speed:.3f} m/s above carrier.speed_limit_mps "
                       f"{cs.speed_limit_mps:g} m/s")
            return
        energy = self._energy()
        limit = max(ENERGY_FLOOR_J, (1.0 + cs.energy_gain_limit) * self._ke_start)
        if self._energy_check and energy > limit:
            gain = math.sqrt(energy / self._ke_start) if self._ke_start > 0 else math.inf
            self._stop(t_s, f"rendering unstable: the target gained energy in a passive "
                       f"contact (speed ratio {gain:.3f} > 1): the loop's delay is at or "
                       "beyond its critical delay")

    def values(self, tip: F64, tool_v: F64) -> tuple[float, ...]:
        """This cycle's record (after :meth:`cycle`)."""
        flange = self.servo.at(self._t)[0]
        return cycle_values(self.body, flange, tip, tool_v, self.measured, self.applied,
                            self.passivity.generated_j, self.passivity.dissipated_j)
