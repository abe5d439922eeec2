"""The KRC's side of the FRI 1.x link as a state machine: states, quality, statistics.

Pure, no I/O and no clock: the owner tells :meth:`KrcLink.cycle` whether the
packet of each cycle was answered in time and how long the answer took. Both
the UDP emulator (:mod:`drivers.fri.emulate.server`) and the in-process
lockstep robot (:mod:`drivers.fri.emulate.lockstep`, every cycle answered unless
the caller skips one) run this one machine.

The machine is the KRL script ``friOpen(ms)``; ``WAIT FOR $FriQuality ==
#PERFECT``; ``friStart(1.0)``; a loop that waits for the interface to leave
#CMD and starts again:

* the link starts in MON;
* MON -> CMD on the cycle where ``start_cycles`` consecutive cycles have been
  answered and the quality is PERFECT (which needs a full window of 100
  packets, so CMD comes on the 100th answered cycle at the earliest);
  ``start_cycles = 0`` is a link that is up already: CMD and PERFECT from the
  first packet;
* CMD -> MON when the quality is UNACCEPTABLE or after
  ``max_consecutive_misses`` misses in a row (the KRC's own rule), or when
  the owner refuses a command (:meth:`KrcLink.refuse`);
* a fault (:meth:`KrcLink.fault`, e.g. a joint at its software limit switch)
  ends CMD and latches an error: the measurement reports it in ``error``
  and the link does not enter CMD again until it is acknowledged
  (:meth:`KrcLink.acknowledge`; on a KRC, the operator).

Quality (:func:`quality_of`, :class:`QualityThresholds`) is rated over the
last 100 packets (:class:`LinkWindow`): answer rate always, latency and
jitter only when ``timing`` (real-time pacing).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum
from typing import Final

import numpy as np

from drivers.fri.types import FriQuality, FriState

__all__ = [
    "ERROR_SOFTWARE_LIMIT",
    "MIN_RATED",
    "WINDOW",
    "KrcLink",
    "LinkEvent",
    "LinkWindow",
    "QualityThresholds",
    "describe_error",
    "quality_of",
]

#: Packets the quality is rated over.
WINDOW: Final = 100
#: Packets in the window before the link can be rated UNACCEPTABLE.
MIN_RATED: Final = 10
#: Error bits of the measurement's ``error`` field set by the emulated KRC (KUKA's
#: error codes are not public; these are ours): bit i (0..6) = joint A(i+1) reached
#: its software limit switch. The KRC then left CMD and holds the robot.
ERROR_SOFTWARE_LIMIT: Final = 0x7F


def describe_error(error: int) -> str:
    """One line for the ``error`` field of a measurement (``""`` for 0)."""
    if error == 0:
        return ""
    parts = []
    joints = [f"A{i + 1}" for i in range(7) if error & ERROR_SOFTWARE_LIMIT & (1 << i)]
    if joints:
        parts.append(f"{', '.join(joints)} at the software limit switch")
    rest = error & ~ERROR_SOFTWARE_LIMIT
    if rest:
        parts.append(f"error bits 0x{rest:x}")
    return "; ".join(parts)


@dataclass(frozen=True)
class QualityThresholds:
    """How the link is rated over the last 100 packets (ours; KUKA's are not public).

    ``miss`` is the fraction of packets not answered in time; latency and
    jitter (mean and standard deviation of send -> answer) are in cycles and
    count only in real-time pacing.

    * PERFECT: a full window without a miss, latency <= ``perfect_latency``,
      jitter <= ``perfect_jitter``;
    * OK: miss <= ``ok_miss``, latency <= ``ok_latency``, jitter <= ``ok_jitter``;
    * BAD: miss <= ``bad_miss`` (commanding is still allowed);
    * UNACCEPTABLE: more misses than that (the KRC leaves command mode).

    An empty window, or one of fewer than 10 packets that would be
    UNACCEPTABLE, is BAD; a window not yet full is at most OK.
    """

    perfect_latency: float = 0.3
    perfect_jitter: float = 0.1
    ok_miss: float = 0.05
    ok_latency: float = 0.6
    ok_jitter: float = 0.2
    bad_miss: float = 0.25


class LinkWindow:
    """answerRate, latency, jitter, missRate over the last ``size`` packets."""

    def __init__(self, size: int = WINDOW) -> None:
        self.size = size
        self.answered = np.zeros(size, dtype=bool)
        self.latency = np.zeros(size)
        self.n = 0
        self.i = 0
        self.rates_cache: tuple[float, float, float, float] | None = None
        """:meth:`rates` as last computed, ``None`` once the window changed (a new tuple
        whenever they may differ: an owner compares it by identity)."""
        # running counts over the window (kept exact: integers)
        self._n_answered = 0
        self._n_latency = 0  # answered packets with a non-zero latency
        # running sums of the latencies (unanswered: 0) and their squares, so that a
        # real-time window costs O(1) per packet; re-summed every window (rounding)
        self._sum = 0.0
        self._sum2 = 0.0
        self._adds = 0

    def add(self, answered: bool, latency_s: float) -> None:
        i = self.i
        lat = latency_s if answered else 0.0
        if self.n == self.size:  # the oldest packet leaves the window
            old_answered = bool(self.answered[i])
            old_latency = float(self.latency[i]) != 0.0
            if old_answered == answered and old_latency == (lat != 0.0) and lat == 0.0:
                # the same kind of packet replaces it: counts and rates stay
                self.i = (i + 1) % self.size
                return
            self._n_answered -= old_answered
            self._n_latency -= old_latency
            old = float(self.latency[i])
            self._sum -= old
            self._sum2 -= old * old
        self.rates_cache = None
        self.answered[i] = answered
        self.latency[i] = lat
        self._n_answered += answered
        self._n_latency += lat != 0.0
        self._sum += lat
        self._sum2 += lat * lat
        self.i = (i + 1) % self.size
        self.n = min(self.n + 1, self.size)
        self._adds += 1
        if self._adds >= self.size:
            self._resum()

    def _resum(self) -> None:
        lat = self.latency[: self.n]
        self._sum = float(lat.sum())
        self._sum2 = float(lat @ lat)
        self._adds = 0

    def fill(self) -> None:
        """A full window of prompt answers (a link that is up already)."""
        self.rates_cache = None
        self.answered[:] = True
        self.latency[:] = 0.0
        self.n = self.size
        self.i = 0
        self._n_answered = self.size
        self._n_latency = 0
        self._sum = self._sum2 = 0.0
        self._adds = 0

    def reset(self) -> None:
        self.rates_cache = None
        self.n = 0
        self.i = 0
        self._n_answered = 0
        self._n_latency = 0
        self._sum = self._sum2 = 0.0
        self._adds = 0

    def rates(self) -> tuple[float, float, float, float]:
        """``(answer_rate, latency_s, jitter_s, miss_rate)``; zeros for an empty window.

        Computed once per change of the window (the KRC rates and reports it every cycle).
        """
        if self.rates_cache is None:
            self.rates_cache = self._compute()
        return self.rates_cache

    def _compute(self) -> tuple[float, float, float, float]:
        n = self.n
        if n == 0:
            return 0.0, 0.0, 0.0, 0.0
        if self._n_latency == 0:  # every answer prompt (lockstep): no array work
            rate = self._n_answered / n
            return rate, 0.0, 0.0, 1.0 - rate
        k = self._n_answered
        rate = k / n
        mean = self._sum / k if k else 0.0
        jitter = math.sqrt(max(self._sum2 / k - mean * mean, 0.0)) if k > 1 else 0.0
        return rate, mean, jitter, 1.0 - rate


def quality_of(
    window: LinkWindow, cycle_s: float, th: QualityThresholds, *, timing: bool
) -> FriQuality:
    """The quality for a window (see :class:`QualityThresholds`)."""
    if window.n == 0:
        return FriQuality.BAD
    _, lat, jit, miss = window.rates()
    lat_c, jit_c = lat / cycle_s, jit / cycle_s
    if miss > th.bad_miss:
        # a few packets say little: an early miss is BAD, not yet UNACCEPTABLE
        return FriQuality.UNACCEPTABLE if window.n >= MIN_RATED else FriQuality.BAD
    ok = miss <= th.ok_miss and (not timing or (lat_c <= th.ok_latency and jit_c <= th.ok_jitter))
    if not ok:
        return FriQuality.BAD
    perfect = (
        window.n == window.size
        and miss == 0.0
        and (not timing or (lat_c <= th.perfect_latency and jit_c <= th.perfect_jitter))
    )
    return FriQuality.PERFECT if perfect else FriQuality.OK


class LinkEvent(Enum):
    """What a cycle did to the link state."""

    NONE = "none"
    START = "start"
    """MON -> CMD (``friStart``): this cycle's answer is the first command taken."""
    FALLBACK = "fallback"
    """CMD -> MON: the KRC stops (holds the measured pose) instead of taking the answer."""


_CMD: Final = FriState.CMD
_UNACCEPTABLE: Final = FriQuality.UNACCEPTABLE
_PERFECT: Final = FriQuality.PERFECT
_NONE: Final = LinkEvent.NONE
_START: Final = LinkEvent.START
_FALLBACK: Final = LinkEvent.FALLBACK


class KrcLink:
    """The KRC's link state machine (module docstring).

    Args:
        cycle_s: the FRI cycle [s] (latencies are rated in cycles).
        start_cycles: consecutive answered cycles before ``friStart`` (0: up already).
        max_consecutive_misses: misses in a row that end command mode.
        thresholds: the quality rating.
        timing: rate latency and jitter (real-time pacing; not in lockstep).
    """

    def __init__(
        self,
        cycle_s: float,
        *,
        start_cycles: int = 100,
        max_consecutive_misses: int = 5,
        thresholds: QualityThresholds | None = None,
        timing: bool = False,
    ) -> None:
        if start_cycles < 0:
            raise ValueError(f"start_cycles must be >= 0, got {start_cycles}")
        if max_consecutive_misses < 1:
            raise ValueError(f"max_consecutive_misses must be >= 1, got {max_consecutive_misses}")
        self.cycle_s = cycle_s
        self.start_cycles = start_cycles
        self.max_consecutive_misses = max_consecutive_misses
        self.thresholds = thresholds if thresholds is not None else QualityThresholds()
        self.timing = timing
        self.window = LinkWindow()
        # (thresholds, timing, cycle_s, the quality of a window full of prompt answers)
        self._prompt: tuple[QualityThresholds, bool, float, FriQuality] | None = None
        self.state = FriState.MON
        self.quality = FriQuality.BAD
        self.consecutive_ok = 0
        self.consecutive_miss = 0
        self.answered = 0
        self.missed = 0
        self.starts = 0
        self.fallbacks = 0
        self.error = 0
        """Latched error bits (:data:`ERROR_SOFTWARE_LIMIT`, ...); 0: none."""
        self.changes = 0
        """Counts the cycles and calls that may have changed what a measurement reports
        of the link (state, quality, error, miss counter, the window's rates): while it
        stays, they are what they were (an owner keeps what it built from them)."""
        if start_cycles == 0:
            self.window.fill()
            self.state = FriState.CMD
            self.quality = FriQuality.PERFECT

    @property
    def commanding(self) -> bool:
        """The KRC takes commands (state CMD)."""
        return self.state == FriState.CMD

    def rates(self) -> tuple[float, float, float, float]:
        """``(answer_rate, latency_s, jitter_s, miss_rate)`` of the window."""
        return self.window.rates()

    def cycle(self, answered: bool, latency_s: float = 0.0) -> LinkEvent:
        """Account one packet: answered in time (with its latency) or missed.

        Updates the window, the quality and the state; returns what changed.
        On :attr:`LinkEvent.START` the state is CMD and this cycle's answer is
        taken; on :attr:`LinkEvent.FALLBACK` the state is MON and the answer
        is not taken (the KRC stops).
        """
        w = self.window
        if answered and latency_s == 0.0 and w._n_answered == w.size and not w._n_latency:
            # a full window of prompt answers gets one more (every lockstep cycle): the
            # window's contents, its rates and hence the quality stay what they are
            w.i = (w.i + 1) % w.size
            self.answered += 1
            self.consecutive_ok += 1
            self.consecutive_miss = 0
            p = self._prompt
            if (p is None or p[0] is not self.thresholds or p[1] is not self.timing
                    or p[2] != self.cycle_s):
                p = self._prompt = (self.thresholds, self.timing, self.cycle_s, quality_of(
                    w, self.cycle_s, self.thresholds, timing=self.timing))
            q = p[3]
            if q is not self.quality:
                self.quality = q
                self.changes += 1
            if self.state == _CMD:
                if q == _UNACCEPTABLE:  # (no miss: only the quality can end it)
                    self._to_mon()
                    return _FALLBACK
            elif self.consecutive_ok >= self.start_cycles and q == _PERFECT and not self.error:
                self.state = _CMD
                self.starts += 1
                self.changes += 1
                return _START
            return _NONE
        return self._account(answered, latency_s)

    def _account(self, answered: bool, latency_s: float) -> LinkEvent:
        """:meth:`cycle` by the window's rule, every case (its fast path's reference)."""
        self.changes += 1
        self.window.add(answered, latency_s)
        if answered:
            self.answered += 1
            self.consecutive_ok += 1
            self.consecutive_miss = 0
        else:
            self.missed += 1
            self.consecutive_ok = 0
            self.consecutive_miss += 1
        q = quality_of(self.window, self.cycle_s, self.thresholds, timing=self.timing)
        self.quality = q
        if self.state == FriState.CMD:
            if (q == FriQuality.UNACCEPTABLE
                    or self.consecutive_miss >= self.max_consecutive_misses):
                self._to_mon()
                return LinkEvent.FALLBACK
        elif (self.consecutive_ok >= self.start_cycles and q == FriQuality.PERFECT
                and not self.error):
            self.state = FriState.CMD
            self.starts += 1
            return LinkEvent.START
        return LinkEvent.NONE

    def refuse(self) -> None:
        """The KRC refused a command (implausible values): back to MON, count from zero."""
        self.changes += 1
        if self.state == FriState.CMD:
            self._to_mon()
        else:
            self.consecutive_ok = 0

    def fault(self, error: int) -> LinkEvent:
        """The KRC stopped the robot for ``error`` (bits): CMD -> MON, the error latched.

        Returns :attr:`LinkEvent.FALLBACK` if this ended command mode.
        """
        self.error |= error
        self.changes += 1
        if self.state == FriState.CMD:
            self._to_mon()
            return LinkEvent.FALLBACK
        self.consecutive_ok = 0
        return LinkEvent.NONE

    def acknowledge(self) -> None:
        """Clear the latched error (the operator acknowledged it); CMD may start again."""
        self.error = 0
        self.consecutive_ok = 0
        self.changes += 1

    def _to_mon(self) -> None:
        self.changes += 1
        self.fallbacks += 1
        self.consecutive_ok = 0
        self.state = FriState.MON
