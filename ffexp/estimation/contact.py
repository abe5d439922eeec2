"""Contact detection on the filtered contact force: hysteresis and debounce. No I/O."""

from __future__ import annotations

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


def contact_settings(config: ContactDetectorConfig) -> F64:
    """One run's detector settings for :mod:`ffexp.estimation.kernels` (``CC_*``)."""
    return np.array([config.on_threshold_n, config.off_threshold_n, config.debounce_on_s,
                     config.debounce_off_s, float(config.signal == "fz")])


_KINDS: tuple[Literal["made", "broken"], ...] = ("made", "broken")


@dataclass
class ContactDetector:
    """Contact state from the filtered wrench, with hysteresis and debounce.

    Contact is declared once the signal has stayed above ``on_threshold_n``
    for ``debounce_on_s``, and lost once it has stayed below
    ``off_threshold_n`` for ``debounce_off_s``; the event carries the time the
    crossing began, not the time it was confirmed. Its arithmetic is
    :func:`ffexp.estimation.kernels.contact_update`, the estimator's own for every
    run of a batch (the estimator keeps :attr:`in_contact` and :attr:`events` of
    each run's detector).
    """

    config: ContactDetectorConfig
    in_contact: bool = False
    events: list[ContactEvent] = field(default_factory=list)

    def __post_init__(self) -> None:
        from ffexp.estimation import kernels

        self._k = kernels
        self._cc = contact_settings(self.config)
        self._cd = np.array([0, kernels.NONE_NS, kernels.NONE_NS], dtype=np.int64)
        self._event = np.zeros(3, dtype=np.int64)

    def signal(self, wrench: F64) -> float:
        """The scalar the thresholds apply to (the force's norm: numpy's bits)."""
        w = np.asarray(wrench, dtype=np.float64)
        return float(self._k.contact_signal(self._cc, w[0], w[1], w[2]))

    def update(self, time_ns: int, wrench: F64) -> ContactEvent | None:
        """Feed one filtered wrench; return the event this sample confirms, if any."""
        self._cd[0] = self.in_contact
        if not self._k.contact_update(self._cd, self._cc, time_ns, self.signal(wrench),
                                      self._event):
            return None
        kind, start, since = self._event.tolist()
        event = ContactEvent(kind=_KINDS[kind - 1], time_ns=start,
                             previous_s=(start - since) * 1e-9)
        self.in_contact = not self.in_contact
        self.events.append(event)
        return event
