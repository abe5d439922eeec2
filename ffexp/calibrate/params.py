"""The scene keys a calibration can fit, their stages and default bounds; ``--fit`` parsing.

Each fittable key belongs to one stage of the identification
(:data:`STAGES`, in the order they run):

- ``timing``: the loop's delay, a whole number of cycles: every value in its
  bounds is replayed and the best kept (exhaustive, exact);
- ``sensor``: the F/T path's delay, whole samples: a shift of the simulated
  series, no rollout (the bias is estimated per recording in every comparison);
- ``smooth``: bed friction, the hose, the joint friction: the measurements move
  smoothly with them, so a box-constrained least squares with finite-difference
  Jacobians (scipy's trust-region reflective) fits them;
- ``contact``: the funnel contact's restitution, stiffness, impedance and
  friction: they act through contact events whose timing and number jump
  with them, so a black-box optimiser (CMA-ES, ``cmaes``) fits them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

from ffexp.calibrate.inputs import flatten
from ffexp.errors import ConfigError

Stage = Literal["timing", "sensor", "smooth", "contact"]
STAGES: tuple[Stage, ...] = ("timing", "sensor", "smooth", "contact")


@dataclass(frozen=True)
class Fittable:
    """A scene key that can be fitted."""

    stage: Stage
    lo: float
    hi: float
    integer: bool = False
    unit: str = ""


#: Every fittable scene key with its stage and default bounds (within the scene's own limits).
FITTABLE: dict[str, Fittable] = {
    "fri.command_delay_cycles": Fittable("timing", 0, 4, integer=True, unit="cycles"),
    "ft_sensor.delay_s": Fittable("sensor", 0.0, 0.01, unit="s"),
    "target.mu": Fittable("smooth", 0.0, 0.02),
    "target.hose.stiffness": Fittable("smooth", 0.0, 20.0, unit="N/m"),
    "target.hose.damping": Fittable("smooth", 0.0, 20.0, unit="N s/m"),
    "arm.friction_scale": Fittable("smooth", 0.0, 0.005),
    "arm.static_ratio": Fittable("smooth", 1.0, 5.0),
    "arm.armature_scale": Fittable("smooth", 0.0, 1.0),
    "arm.torque_loop_r": Fittable("smooth", 0.0, 1.0),
    "contact.restitution": Fittable("contact", 0.001, 0.99),
    "contact.stiffness": Fittable("contact", 2.0e3, 2.0e5, unit="N/m"),
    "contact.impedance": Fittable("contact", 0.05, 0.95),
    "contact.friction": Fittable("contact", 0.0, 1.0),
}


@dataclass(frozen=True)
class Param:
    """One parameter of a fit: its key, bounds and start value (the base scene's)."""

    key: str
    lo: float
    hi: float
    start: float
    spec: Fittable

    @property
    def stage(self) -> Stage:
        return self.spec.stage

    @property
    def integer(self) -> bool:
        return self.spec.integer

    def to_unit(self, value: float) -> float:
        return (value - self.lo) / (self.hi - self.lo)

    def from_unit(self, u: float) -> float:
        v = self.lo + min(max(u, 0.0), 1.0) * (self.hi - self.lo)
        return float(round(v)) if self.integer else v

    def value(self, v: float) -> int | float:
        """``v`` as the scene types it."""
        return round(v) if self.integer else float(v)


def parse_fit(texts: Sequence[str], scene: Mapping[str, Any], where: str = "--fit") -> list[Param]:
    """``KEY`` or ``KEY=LO:HI`` options as parameters, their start values from ``scene``.

    Raises :class:`ConfigError` (exit 2) naming the option for a key that is not a
    fittable scene parameter, malformed or empty bounds, bounds outside the
    key's limits, or bounds that exclude the start value.
    """
    flat = flatten(scene)
    params: list[Param] = []
    for text in texts:
        key, sep, rng = text.partition("=")
        key = key.strip()
        spec = FITTABLE.get(key)
        if spec is None:
            what = ("a scene key that cannot be fitted" if key in flat
                    else "not a scene parameter")
            raise ConfigError(where, text, f"{key!r} is {what}; fittable: "
                              f"{', '.join(FITTABLE)}")
        if any(p.key == key for p in params):
            raise ConfigError(where, text, f"{key} is given twice")
        lo, hi = spec.lo, spec.hi
        if sep:
            a, colon, b = rng.partition(":")
            try:
                if not colon:
                    raise ValueError
                lo, hi = float(a), float(b)
                if not (math.isfinite(lo) and math.isfinite(hi)):
                    raise ValueError
            except ValueError:
                raise ConfigError(where, text, "expected KEY=LO:HI with two finite "
                                  "numbers") from None
            if not lo < hi:
                raise ConfigError(where, text, f"empty bounds: {lo:g} is not below {hi:g}")
            if lo < spec.lo or hi > spec.hi:
                raise ConfigError(where, text, f"bounds outside {key}'s limits "
                                  f"[{spec.lo:g}, {spec.hi:g}]")
        if flat.get(key) is None:  # an optional key the base scene leaves unset
            raise ConfigError(where, text, f"the base scene does not set {key}; give it a "
                              "start value in the scene file")
        start = float(flat[key])
        if not lo <= start <= hi:
            raise ConfigError(where, text, f"bounds [{lo:g}, {hi:g}] exclude the start value "
                              f"{start:g} (the base scene's {key})")
        params.append(Param(key, lo, hi, start, spec))
    if not params:
        raise ConfigError(where, "", "nothing to fit: give at least one --fit KEY")
    order = {s: i for i, s in enumerate(STAGES)}
    return sorted(params, key=lambda p: (order[p.stage], list(FITTABLE).index(p.key)))
