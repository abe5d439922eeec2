"""Contact detection on the filtered contact force: hysteresis and debounce. No I/O."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from drivers.base.types import F64
from drivers.config import StrictModel


class ContactDetectorConfig(StrictModel):
    """Hysteresis and debounce on the filtered contact force.

    ``signal`` picks what is compared: the norm of the force vector, or the
    approach-axis contact force ``f_z = -w[2]``.
    """

    signal: Literal["force_norm", "fz"] = "force_norm"
    on_threshold_n: float = Field(0.3, gt=0)
    off_threshold_n: float = Field(0.1, ge=0)
    debounce_on_s: float = Field(0.01, ge=0)
    debounce_off_s: float = Field(0.05, ge=0)

    @model_validator(mode="after")
    def _hysteresis(self) -> ContactDetectorConfig:
        if self.off_threshold_n >= self.on_threshold_n:
            raise ValueError("off_threshold_n must be below on_threshold_n")
        return self


@dataclass(frozen=True)
class ContactEvent:
    """Contact made or broken at ``time_ns``; ``previous_s`` is how long the
    previous state (free or in contact) lasted."""

    kind: Literal["made", "broken"]
    time_ns: int
    previous_s: float


@dataclass
class ContactDetector:
    """Contact state from the filtered wrench, with hysteresis and debounce.

    Contact is declared once the signal has stayed above ``on_threshold_n``
    for ``debounce_on_s``, and lost once it has stayed below
    ``off_threshold_n`` for ``debounce_off_s``; the event carries the time the
    crossing began, not the time it was confirmed.
    """

    config: ContactDetectorConfig
    in_contact: bool = False
    events: list[ContactEvent] = field(default_factory=list)
    _pending_since_ns: int | None = None
    _state_since_ns: int | None = None

    def signal(self, wrench: F64) -> float:
        """The scalar the thresholds apply to."""
        if self.config.signal == "fz":
            return float(-wrench[2])
        if type(wrench) is np.ndarray and wrench.dtype == np.float64:
            f = wrench[:3]  # np.linalg.norm's own sum of squares and root, without its checks
            return math.sqrt(f.dot(f))
        return float(np.linalg.norm(wrench[:3]))

    def update(self, time_ns: int, wrench: F64) -> ContactEvent | None:
        """Feed one filtered wrench; return the event this sample confirms, if any."""
        if self._state_since_ns is None:
            self._state_since_ns = time_ns
        s = self.signal(wrench)
        crossing = s < self.config.off_threshold_n if self.in_contact else (
            s > self.config.on_threshold_n
        )
        if not crossing:
            self._pending_since_ns = None
            return None
        if self._pending_since_ns is None:
            self._pending_since_ns = time_ns
        hold_s = self.config.debounce_off_s if self.in_contact else self.config.debounce_on_s
        if (time_ns - self._pending_since_ns) * 1e-9 + 1e-12 < hold_s:
            return None
        start = self._pending_since_ns
        event = ContactEvent(
            kind="broken" if self.in_contact else "made",
            time_ns=start,
            previous_s=(start - self._state_since_ns) * 1e-9,
        )
        self.in_contact = not self.in_contact
        self._state_since_ns = start
        self._pending_since_ns = None
        self.events.append(event)
        return event
