"""Counters of the FRI remote link and their snapshot, :class:`LinkStats`.

:class:`LinkCounters` is mutated by the driver's I/O thread under the driver's
lock; :meth:`LinkCounters.snapshot` turns it into an immutable
:class:`LinkStats` for logs and tests.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import NDArray

from drivers.fri.codec import DecodeStats
from drivers.fri.types import FriMeasurement, FriQuality, FriState, RemoteMeasurement

__all__ = ["TURNAROUND_CAPACITY", "LinkCounters", "LinkStats", "LinkWatch"]

#: Turnaround times kept (a ring buffer): about 11 minutes at 5 ms.
TURNAROUND_CAPACITY: Final = 1 << 17


@dataclass(frozen=True)
class LinkStats:
    """A snapshot of the link, for logs (driver counters and the KRC's own view)."""

    received: int
    """Datagrams received on the port (any source)."""
    foreign: int
    """Datagrams from an address other than the robot's, dropped."""
    foreign_address: tuple[str, int] | None
    """The last foreign sender (``None``: none)."""
    decode: dict[str, int]
    """Codec outcome counts of the robot's datagrams (ok, too_short, wrong_id, ...)."""
    accepted: int
    """Measurements accepted (new sequence numbers)."""
    duplicates: int
    stale: int
    """Reordered (older) measurements, dropped."""
    lost: int
    """Measurements missing in the sequence (gaps) and never received late."""
    restarts: int
    implausible: int
    """Measurements with a header but impossible contents (sample time, NaN), dropped."""
    answers: int
    """Command datagrams sent (including re-answers of duplicates)."""
    runner_answers: int
    """Cycles answered with the runner's command for that very cycle."""
    deadline_answers: int
    """Cycles answered at the deadline with the previous command (runner late)."""
    runner_late: int
    """Runner commands that came after their cycle had been answered."""
    skipped: int
    """Measurements the runner never saw (it fell behind by a cycle or more)."""
    turnaround_last_s: float
    """Packet received -> answer sent, last cycle."""
    turnaround_max_s: float
    state: FriState
    quality: FriQuality
    answer_rate: float
    latency_s: float
    jitter_s: float
    miss_rate: float
    miss_counter: int
    fallbacks: int
    """Times the KRC left command mode."""
    link_lost: bool
    """The KRC left command mode (or quality is UNACCEPTABLE) after having commanded."""


class LinkCounters:
    """The mutable counters behind :class:`LinkStats` (not thread-safe: the owner locks)."""

    def __init__(self) -> None:
        self.decode = DecodeStats()
        self.received = 0
        self.foreign = 0
        self.foreign_address: tuple[str, int] | None = None
        self.foreign_ipv4 = 0
        self.accepted = 0
        self.duplicates = 0
        self.stale = 0
        self.lost = 0
        self.restarts = 0
        self.implausible = 0
        self.answers = 0
        self.runner_answers = 0
        self.deadline_answers = 0
        self.runner_late = 0
        self.skipped = 0
        self.fallbacks = 0
        self.was_cmd = False
        self.state = FriState.OFF
        self.quality = FriQuality.INVALID
        self.krc = (0.0, 0.0, 0.0, 0.0, 0)
        self._turn = np.zeros(TURNAROUND_CAPACITY, dtype=np.int64)
        self._turn_n = 0
        self._turn_max = 0

    def on_measurement(self, m: FriMeasurement) -> None:
        """Take the KRC's state, quality and own link statistics from an accepted measurement."""
        self.accepted += 1
        if m.state == FriState.CMD:
            self.was_cmd = True
        elif self.state == FriState.CMD:
            self.fallbacks += 1
        self.state = m.state
        self.quality = m.quality
        self.krc = (m.answer_rate, m.latency_s, m.jitter_s, m.miss_rate, m.miss_counter)

    def on_answer(self, turnaround_ns: int) -> None:
        """Count one answered cycle that took ``turnaround_ns`` from packet to answer."""
        self._turn[self._turn_n % TURNAROUND_CAPACITY] = turnaround_ns
        self._turn_n += 1
        self._turn_max = max(self._turn_max, turnaround_ns)
        self.answers += 1

    def on_foreign(self, addr: tuple[str, int]) -> bool:
        """Count a datagram from ``addr`` (not the robot); True when the sender is new."""
        self.foreign += 1
        if self.foreign_address is not None and addr == self.foreign_address:
            return False
        host, port = addr[0], int(addr[1])
        self.foreign_address = (host, port)
        parts = host.split(".")
        self.foreign_ipv4 = (
            int.from_bytes(bytes(int(p) for p in parts), "big")
            if len(parts) == 4 and all(p.isdigit() for p in parts) else 0
        )
        return True

    def fill(self, m: RemoteMeasurement) -> None:
        """Copy the counters into ``m`` (its ``/robot/link_driver`` fields), no allocation."""
        d = self.decode
        m.received = self.received
        m.foreign = self.foreign
        m.foreign_ipv4 = self.foreign_ipv4
        m.foreign_port = self.foreign_address[1] if self.foreign_address is not None else 0
        m.rejected = d.total - d.ok
        m.accepted = self.accepted
        m.lost = self.lost
        m.duplicates = self.duplicates
        m.reordered = self.stale
        m.restarts = self.restarts
        m.implausible = self.implausible
        m.answers = self.answers
        m.runner_answers = self.runner_answers
        m.deadline_answers = self.deadline_answers
        m.runner_late = self.runner_late
        m.skipped = self.skipped
        n = self._turn_n
        m.turnaround_s = int(self._turn[(n - 1) % TURNAROUND_CAPACITY]) * 1e-9 if n else 0.0

    def turnarounds_ns(self) -> NDArray[np.int64]:
        """Receive -> answer times of the answered cycles so far, oldest first (a copy)."""
        n = self._turn_n
        if n <= TURNAROUND_CAPACITY:
            return self._turn[:n].copy()
        k = n % TURNAROUND_CAPACITY
        return np.concatenate([self._turn[k:], self._turn[:k]])

    def snapshot(self) -> LinkStats:
        ar, lat, jit, mr, mc = self.krc
        last = self._turn[(self._turn_n - 1) % TURNAROUND_CAPACITY] if self._turn_n else 0
        lost = self.was_cmd and (
            self.state != FriState.CMD or self.quality == FriQuality.UNACCEPTABLE
        )
        return LinkStats(
            received=self.received,
            foreign=self.foreign,
            foreign_address=self.foreign_address,
            decode=self.decode.as_dict(),
            accepted=self.accepted,
            duplicates=self.duplicates,
            stale=self.stale,
            lost=self.lost,
            restarts=self.restarts,
            implausible=self.implausible,
            answers=self.answers,
            runner_answers=self.runner_answers,
            deadline_answers=self.deadline_answers,
            runner_late=self.runner_late,
            skipped=self.skipped,
            turnaround_last_s=int(last) * 1e-9,
            turnaround_max_s=self._turn_max * 1e-9,
            state=self.state,
            quality=self.quality,
            answer_rate=ar,
            latency_s=lat,
            jitter_s=jit,
            miss_rate=mr,
            miss_counter=mc,
            fallbacks=self.fallbacks,
            link_lost=lost,
        )


class LinkWatch:
    """Notices every change of the KRC's state and quality in a stream of measurements
    and describes it as an event ``(KRC time [ns], level, name, message)``."""

    def __init__(self) -> None:
        self.state: FriState | None = None
        self.quality: FriQuality | None = None

    def see(self, m: FriMeasurement, out: list[tuple[int, str, str, str]]) -> None:
        """Append to ``out`` what changed with ``m`` (nothing, most cycles)."""
        state, quality = m.state, m.quality
        if state == self.state and quality == self.quality:
            return
        if self.state is None:
            out.append((m.time_ns, "INFO", "link",
                        f"FRI link up: state {state.name}, quality {quality.name}"))
        else:
            if state != self.state:
                level = "WARNING" if self.state == FriState.CMD else "INFO"
                out.append((m.time_ns, level, "link",
                            f"FRI state {self.state.name} -> {state.name} "
                            f"(quality {quality.name}, seq {m.seq})"))
            if quality != self.quality:
                assert self.quality is not None
                level = ("ERROR" if quality <= FriQuality.UNACCEPTABLE else
                         "WARNING" if quality < self.quality else "INFO")
                out.append((m.time_ns, level, "link",
                            f"FRI quality {self.quality.name} -> {quality.name} "
                            f"(answer rate {m.answer_rate:.2f}, seq {m.seq})"))
        self.state, self.quality = state, quality
