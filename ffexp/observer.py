"""Alignment without a view of the target: the wrench-and-kinematics observer.

Pure: no I/O, no clock. Without ground truth or a tracker, nothing measured at
the robot alone fixes where the target is (it floats and moves with the
tool), so the observer answers in three words and says why:

- ``"aligned"`` only when every robot-side sign of seated cones holds together
  for ``observer_hold_s``: the tool pushes (``f_z >= observer_min_force_n``)
  with no lateral force or torque about the vertical (``|f_y|``,
  ``|t_x|``: a tool resting on one side of a cone feels the cone's normal),
  neither slides sideways nor turns (lateral speed and yaw rate), and it has
  advanced at least the funnel's seated depth since first contact *more
  than the target could have been pushed meanwhile* (the target's possible
  travel is bounded by the impulse the tool gave it: ``∫ f_z dt / m_target``
  integrated twice, minus nothing for friction, so the bound is generous);
- ``"not aligned"`` when the evidence contradicts seating, held for
  ``observer_hold_s``: the tool rests on one wall of the funnel (a lateral
  force above ``lateral_force_n`` and at least ``wall_force_ratio`` times the
  push: a 30 degree cone wall's normal has about 1.7 N of lateral force per
  newton of push, 0.9 with a friction of 0.3; seated cones cancel it), or the
  tool is out of contact *behind* the point where it first touched (the
  target is only ever pushed away, so the funnels are apart). Out of contact
  elsewhere says nothing: seated cones that stopped pushing look the same;
- ``"unverified"`` otherwise: the robot's view is consistent with seating
  but cannot prove it (or it shows nothing either way).

The bound on the target's travel is what the old rule ("advanced 30 mm with
no lateral force") lacked: a free-floating target pushed along the approach
axis lets the tool advance any distance without entering the funnel.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from drivers.base.types import NS_PER_S

Label = Literal["aligned", "not aligned", "unverified"]


@dataclass(frozen=True)
class ObserverLimits:
    """The observer's thresholds (from the protocol's ``[alignment]``)."""

    seated_depth_m: float
    lateral_force_n: float
    lateral_torque_nm: float
    wall_force_ratio: float
    min_force_n: float
    lateral_speed_mps: float
    yaw_rate_radps: float
    hold_s: float
    target_mass_kg: float


@dataclass
class ObserverState:
    """What the observer has seen so far (updated in place each cycle)."""

    label: Label = "unverified"
    last: tuple[float, ...] = ()
    """The last cycle's numbers (see :attr:`evidence`), kept without building a dict."""
    quiet_since_ns: int | None = None
    ever_quiet: bool = False
    """The quiet push (the robot-side sign of seated cones) has held for ``hold_s`` at
    some time since first contact."""
    """Since when the wrench and the motion have been quiet (``None``: not now)."""
    loaded_since_ns: int | None = None
    """Since when the tool has been on one wall, or apart (``None``: not now)."""
    first_contact_z: float | None = None
    impulse_ns: float = 0.0
    """``∫ f_z dt`` since first contact [N s]."""
    travel_bound_m: float = 0.0
    """Largest distance the target can have moved along the approach since first contact [m]."""
    speed_bound_mps: float = 0.0
    last_ns: int | None = None

    @property
    def evidence(self) -> dict[str, float]:
        """The numbers the label rests on (SI units in the names)."""
        if not self.last:
            return {}
        names = ("advance_m", "inserted_bound_m", "f_z_n", "f_y_n", "t_x_nm", "v_y_mps",
                 "w_x_radps", "in_contact")
        out = dict(zip(names, self.last, strict=True))
        now = self.last_ns or 0
        out["target_travel_bound_m"] = self.travel_bound_m
        out["ever_quiet"] = float(self.ever_quiet)
        out["quiet_s"] = 0.0 if self.quiet_since_ns is None else \
            (now - self.quiet_since_ns) / NS_PER_S
        out["wall_or_apart_s"] = 0.0 if self.loaded_since_ns is None else \
            (now - self.loaded_since_ns) / NS_PER_S
        return out


class WrenchObserver:
    """Judges alignment from the contact wrench and the tool's motion alone."""

    def __init__(self, limits: ObserverLimits) -> None:
        self.limits = limits
        self.state = ObserverState()
        self._hold_ns = limits.hold_s * NS_PER_S

    def contact_made(self, z_m: float) -> None:
        """The first contact: the tool's position along its approach axis [m]."""
        if self.state.first_contact_z is None:
            self.state.first_contact_z = z_m

    def final(self) -> Label:
        """The run's label at its end (the current one). A run that never showed the
        quiet push is *not* called "not aligned": in the simulator, runs whose cones
        seated did not always show it for ``hold_s`` (measured with
        ``benchmarks/observer_confusion.py``: 10 of 37), so its absence proves nothing."""
        return self.state.label

    def update(self, t_ns: int, z_m: float, in_contact: bool, f_z: float, f_y: float,
               t_x: float, v_y: float, w_x: float) -> Label:
        """One cycle: the tool's advance ``z_m`` (start TCF), contact, wrench (TCF,
        ``f_z`` pushing positive) and lateral speed and yaw rate; returns this
        cycle's label (before any hold on ``"aligned"``'s evidence: held here)."""
        lim, s = self.limits, self.state
        dt = 0.0 if s.last_ns is None else (t_ns - s.last_ns) / NS_PER_S
        s.last_ns = t_ns
        if s.first_contact_z is not None and dt > 0.0:
            push = max(f_z, 0.0)  # the tool only pushes the target away
            s.speed_bound_mps += push * dt / lim.target_mass_kg
            s.travel_bound_m += s.speed_bound_mps * dt
            s.impulse_ns += push * dt
        advance = 0.0 if s.first_contact_z is None else z_m - s.first_contact_z
        side = in_contact and (abs(f_y) > lim.lateral_force_n or abs(t_x) > lim.lateral_torque_nm)
        quiet = (in_contact and f_z >= lim.min_force_n and not side
                 and abs(v_y) <= lim.lateral_speed_mps and abs(w_x) <= lim.yaw_rate_radps)
        on_wall = (in_contact and abs(f_y) > lim.lateral_force_n
                   and abs(f_y) >= lim.wall_force_ratio * max(f_z, 0.0))
        apart = (not in_contact and s.first_contact_z is not None and advance < 0.0)
        s.quiet_since_ns = (s.quiet_since_ns if s.quiet_since_ns is not None else t_ns) \
            if quiet else None
        s.loaded_since_ns = (s.loaded_since_ns if s.loaded_since_ns is not None else t_ns) \
            if on_wall or apart else None
        hold_ns = self._hold_ns
        inserted = advance - s.travel_bound_m
        s.last = (advance, inserted, f_z, f_y, t_x, v_y, w_x, float(in_contact))
        quiet_held = s.quiet_since_ns is not None and t_ns - s.quiet_since_ns >= hold_ns
        if quiet_held and s.first_contact_z is not None:
            s.ever_quiet = True
        if quiet_held and inserted >= lim.seated_depth_m:
            s.label = "aligned"
        elif s.loaded_since_ns is not None and t_ns - s.loaded_since_ns >= hold_ns:
            s.label = "not aligned"
        else:
            s.label = "unverified"
        return s.label
