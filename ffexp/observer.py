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
from types import ModuleType
from typing import Literal

import numpy as np

from drivers.base.types import NS_PER_S

Label = Literal["aligned", "not aligned", "unverified"]


def kernels() -> ModuleType:
    """:mod:`ffexp.controllers.kernels` (the observer's compiled cycle), imported on first
    use (numba's import is slow)."""
    from ffexp.controllers import kernels as module

    return module


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


class ObserverState:
    """What the observer has seen so far: views of its state rows (updated in place each
    cycle by the compiled cycle, :func:`ffexp.controllers.kernels.observer_update`)."""

    def __init__(self) -> None:
        k = self._k = kernels()
        self.floats = np.zeros(k.OBF_SIZE)
        """``OBF_*`` of :mod:`ffexp.controllers.kernels`."""
        self.ints = np.zeros(k.OBI_SIZE, dtype=np.int64)
        """``OBI_*``."""
        self.ints[[k.OBI_LAST_NS, k.OBI_QUIET, k.OBI_LOADED]] = k.NONE_NS

    def _time(self, col: int) -> int | None:
        value = int(self.ints[col])
        return None if value == self._k.NONE_NS else value

    @property
    def label(self) -> Label:
        return self._k.LABELS[self.ints[self._k.OBI_LABEL]]  # type: ignore[no-any-return]

    @property
    def last(self) -> tuple[float, ...]:
        """The last cycle's numbers (see :attr:`evidence`)."""
        k = self._k
        if not self.ints[k.OBI_HAS_LAST]:
            return ()
        return tuple(self.floats[k.OBF_LAST:k.OBF_LAST + 8].tolist())

    @property
    def quiet_since_ns(self) -> int | None:
        """Since when the wrench and the motion have been quiet (``None``: not now)."""
        return self._time(self._k.OBI_QUIET)

    @property
    def ever_quiet(self) -> bool:
        """The quiet push (the robot-side sign of seated cones) has held for ``hold_s`` at
        some time since first contact."""
        return bool(self.ints[self._k.OBI_EVER_QUIET])

    @property
    def loaded_since_ns(self) -> int | None:
        """Since when the tool has been on one wall, or apart (``None``: not now)."""
        return self._time(self._k.OBI_LOADED)

    @property
    def first_contact_z(self) -> float | None:
        k = self._k
        return float(self.floats[k.OBF_FIRST_Z]) if self.ints[k.OBI_HAS_FIRST] else None

    @first_contact_z.setter
    def first_contact_z(self, z_m: float | None) -> None:
        k = self._k
        self.ints[k.OBI_HAS_FIRST] = z_m is not None
        self.floats[k.OBF_FIRST_Z] = 0.0 if z_m is None else z_m

    @property
    def impulse_ns(self) -> float:
        """``∫ f_z dt`` since first contact [N s]."""
        return float(self.floats[self._k.OBF_IMPULSE])

    @property
    def travel_bound_m(self) -> float:
        """Largest distance the target can have moved along the approach since first
        contact [m]."""
        return float(self.floats[self._k.OBF_TRAVEL])

    @property
    def speed_bound_mps(self) -> float:
        return float(self.floats[self._k.OBF_SPEED])

    @property
    def last_ns(self) -> int | None:
        return self._time(self._k.OBI_LAST_NS)

    @property
    def evidence(self) -> dict[str, float]:
        """The numbers the label rests on (SI units in the names)."""
        last = self.last
        if not last:
            return {}
        names = ("advance_m", "inserted_bound_m", "f_z_n", "f_y_n", "t_x_nm", "v_y_mps",
                 "w_x_radps", "in_contact")
        out = dict(zip(names, last, strict=True))
        now = self.last_ns or 0
        quiet, loaded = self.quiet_since_ns, self.loaded_since_ns
        out["target_travel_bound_m"] = self.travel_bound_m
        out["ever_quiet"] = float(self.ever_quiet)
        out["quiet_s"] = 0.0 if quiet is None else (now - quiet) / NS_PER_S
        out["wall_or_apart_s"] = 0.0 if loaded is None else (now - loaded) / NS_PER_S
        return out


class WrenchObserver:
    """Judges alignment from the contact wrench and the tool's motion alone."""

    def __init__(self, limits: ObserverLimits) -> None:
        self.limits = limits
        self.state = ObserverState()
        self._hold_ns = limits.hold_s * NS_PER_S
        k = self._k = kernels()
        lim = self.lims = np.zeros(k.OBL_SIZE)
        """The limits as the compiled cycle takes them (``OBL_*``)."""
        lim[k.OBL_SEATED], lim[k.OBL_LAT_F] = limits.seated_depth_m, limits.lateral_force_n
        lim[k.OBL_LAT_T], lim[k.OBL_WALL] = limits.lateral_torque_nm, limits.wall_force_ratio
        lim[k.OBL_MIN_F], lim[k.OBL_LAT_V] = limits.min_force_n, limits.lateral_speed_mps
        lim[k.OBL_YAW], lim[k.OBL_HOLD_NS] = limits.yaw_rate_radps, self._hold_ns
        lim[k.OBL_MASS] = limits.target_mass_kg

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
        cycle's label (before any hold on ``"aligned"``'s evidence: held here).
        Compiled (:func:`ffexp.controllers.kernels.observer_update`); :func:`update_floats`
        is the same on Python floats."""
        s = self.state
        code = self._k.observer_update(s.floats, s.ints, self.lims, t_ns, float(z_m),
                                       bool(in_contact), float(f_z), float(f_y), float(t_x),
                                       float(v_y), float(w_x))
        return self._k.LABELS[code]  # type: ignore[no-any-return]


def update_floats(lim: ObserverLimits, s: dict[str, object], t_ns: int, z_m: float,
                  in_contact: bool, f_z: float, f_y: float, t_x: float, v_y: float,
                  w_x: float) -> Label:
    """:meth:`WrenchObserver.update` on Python floats, its state a dict of
    :class:`ObserverState`'s fields (the reference of the compiled form)."""
    last_ns = s["last_ns"]
    dt = 0.0 if last_ns is None else (t_ns - last_ns) / NS_PER_S  # type: ignore[operator]
    s["last_ns"] = t_ns
    first = s["first_contact_z"]
    if first is not None and dt > 0.0:
        push = max(f_z, 0.0)  # the tool only pushes the target away
        s["speed_bound_mps"] += push * dt / lim.target_mass_kg  # type: ignore[operator]
        s["travel_bound_m"] += s["speed_bound_mps"] * dt  # type: ignore[operator]
        s["impulse_ns"] += push * dt  # type: ignore[operator]
    advance = 0.0 if first is None else z_m - first  # type: ignore[operator]
    side = in_contact and (abs(f_y) > lim.lateral_force_n or abs(t_x) > lim.lateral_torque_nm)
    quiet = (in_contact and f_z >= lim.min_force_n and not side
             and abs(v_y) <= lim.lateral_speed_mps and abs(w_x) <= lim.yaw_rate_radps)
    on_wall = (in_contact and abs(f_y) > lim.lateral_force_n
               and abs(f_y) >= lim.wall_force_ratio * max(f_z, 0.0))
    apart = (not in_contact and first is not None and advance < 0.0)
    qs, ls = s["quiet_since_ns"], s["loaded_since_ns"]
    s["quiet_since_ns"] = (qs if qs is not None else t_ns) if quiet else None
    s["loaded_since_ns"] = (ls if ls is not None else t_ns) if on_wall or apart else None
    hold_ns = lim.hold_s * NS_PER_S
    inserted = advance - s["travel_bound_m"]  # type: ignore[operator]
    s["last"] = (advance, inserted, f_z, f_y, t_x, v_y, w_x, float(in_contact))
    qs = s["quiet_since_ns"]
    quiet_held = qs is not None and t_ns - qs >= hold_ns  # type: ignore[operator]
    if quiet_held and first is not None:
        s["ever_quiet"] = True
    ls = s["loaded_since_ns"]
    label: Label
    if quiet_held and inserted >= lim.seated_depth_m:
        label = "aligned"
    elif ls is not None and t_ns - ls >= hold_ns:  # type: ignore[operator]
        label = "not aligned"
    else:
        label = "unverified"
    s["label"] = label
    return label
