"""The typed contracts between the experiment loop and everything that reads its results.

:class:`Phase` and :class:`StopReason` are recorded on ``/runner/phase``
(``phase_id`` and ``stop_reason``) and read back by :mod:`ffexp.analysis`, so
neither side compares free text. A low module: it imports nothing of ffexp.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field


class Phase(enum.IntEnum):
    """The experiment's phases (``/runner/phase`` ``phase_id``, ``/control/terms`` ``phase``)."""

    CONNECT = 0
    """Link up, the robot holds its own set-point while the F/T sensor is tared."""
    APPROACH = 1
    """External impedance law, set-point moving along the approach line."""
    ALIGN = 2
    """In contact: the method's controller (``[align] method``)."""
    DONE = 3
    """Aligned (held for ``alignment.hold_s``) or timed out; safe stop."""
    ABORT = 4
    """A safety limit, a device fault or a stop request; safe stop."""

    @property
    def ended(self) -> bool:
        return self in (Phase.DONE, Phase.ABORT)


class StopReason(enum.Enum):
    """Why a run ended. ``value`` is what the recording stores."""

    ALIGNED = "aligned"
    TIMEOUT = "timeout"
    FORCE_LIMIT = "force_limit"
    TORQUE_LIMIT = "torque_limit"
    SPEED_LIMIT = "speed_limit"
    WORKSPACE_LIMIT = "workspace_limit"
    FT_SATURATED = "ft_saturated"
    FT_STALE = "ft_stale"
    LINK_BAD = "link_bad"
    """The robot stopped commanding, or its link quality was unacceptable, too long."""
    LINK_LOST = "link_lost"
    """The driver reported the link lost."""
    ROBOT_TIMEOUT = "robot_timeout"
    """The driver waited for a cycle that did not come."""
    NO_MEASUREMENT = "no_measurement"
    """The robot never sent a state: nothing was received within the connect timeout."""
    DRIVER_ERROR = "driver_error"
    """Any other device error (bad command, diverged simulation, ...)."""
    STOP_REQUESTED = "stop_requested"
    ROBOT_STOPPED = "robot_stopped"
    """The robot stopped sending states without an error."""

    @property
    def phase(self) -> Phase:
        """DONE for the two normal ends, ABORT for everything else."""
        return Phase.DONE if self in (StopReason.ALIGNED, StopReason.TIMEOUT) else Phase.ABORT


@dataclass(frozen=True)
class Stop:
    """A reason to end the run, with the one-line message for the events."""

    reason: StopReason
    message: str


@dataclass
class Progress:
    """What the live progress line shows."""

    phase: Phase
    time_s: float
    f_z_n: float
    contacts: int
    breaks: int


@dataclass
class RunOutcome:
    """How a run ended (the numbers come from the recording: ffexp.analysis)."""

    phase: Phase
    aligned: bool
    stop_reason: StopReason
    reason: str
    cycles: int
    duration_s: float
    contacts: int
    breaks: int
    events: list[tuple[float, str, str]] = field(default_factory=list)
