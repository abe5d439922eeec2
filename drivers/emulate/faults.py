"""Injected network faults of the emulated KRC's UDP link (loss, delay, jitter, duplicates, ...).

Seeded: the same :class:`FaultSettings` give the same faults for the same
traffic. Every datagram in either direction is lost with probability
``loss``; outgoing datagrams get a delay ``delay_s + |N(0, jitter_s)|``, are
sent twice with probability ``duplicate``, held back 1.5 cycles (so the next
overtakes them) with probability ``reorder``, and get 1-4 random bytes
overwritten (each in the 8-byte header with probability 1/2) with
probability ``corrupt``.
"""

from __future__ import annotations

import heapq
import socket
from dataclasses import dataclass, field

import numpy as np

__all__ = ["FaultCounters", "FaultSettings", "FaultyLink"]


@dataclass(frozen=True)
class FaultSettings:
    """Injected network faults (probabilities in 0..1, times in s)."""

    loss: float = 0.0
    delay_s: float = 0.0
    jitter_s: float = 0.0
    duplicate: float = 0.0
    reorder: float = 0.0
    corrupt: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("loss", "duplicate", "reorder", "corrupt"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"{name} must be a probability in 0..1, got {v}")
        if self.delay_s < 0 or self.jitter_s < 0:
            raise ValueError("delay and jitter must be >= 0")

    @property
    def any(self) -> bool:
        return any((self.loss, self.delay_s, self.jitter_s, self.duplicate, self.reorder,
                    self.corrupt))


@dataclass
class FaultCounters:
    """What the injected faults did.

    The ``*_seqs`` lists hold the ``sendSeqCount`` (the first two bytes of an
    FRI datagram, little endian) of each outgoing datagram a fault hit, so a test
    can tell what a remote should have seen up to a given packet.
    """

    dropped_out: int = 0
    dropped_in: int = 0
    duplicated: int = 0
    reordered: int = 0
    corrupted: int = 0
    dropped_out_seqs: list[int] = field(default_factory=list)
    duplicated_seqs: list[int] = field(default_factory=list)
    reordered_seqs: list[int] = field(default_factory=list)


class FaultyLink:
    """Applies :class:`FaultSettings` to one UDP socket (inactive: a plain socket).

    Args:
        sock: the bound socket.
        faults: what to inject.
        cycle_s: the link's cycle (a reordered datagram is held 1.5 cycles).
        counters: where to count (e.g. the emulator's stats).
    """

    def __init__(self, sock: socket.socket, faults: FaultSettings, cycle_s: float,
                 counters: FaultCounters) -> None:
        self.sock = sock
        self.f = faults
        self.cycle_s = cycle_s
        self.stats = counters
        self.rng = np.random.default_rng(faults.seed)
        self.queue: list[tuple[float, int, bytes, tuple[str, int]]] = []
        self._k = 0
        self.active = True

    def send(self, data: bytes, addr: tuple[str, int], now: float) -> bool:
        """Send, delay, duplicate or damage ``data``; False: dropped (nothing goes out)."""
        f = self.f
        if not f.any or not self.active:
            self._sendto(data, addr)
            return True
        rng = self.rng
        seq = int.from_bytes(data[:2], "little")
        if f.loss and rng.random() < f.loss:
            self.stats.dropped_out += 1
            self.stats.dropped_out_seqs.append(seq)
            return False
        if f.corrupt and rng.random() < f.corrupt:
            b = bytearray(data)
            for _ in range(int(rng.integers(1, 5))):
                # half of the damage in the 8-byte header, so that some is detectable
                end = 8 if rng.random() < 0.5 else len(b)
                b[int(rng.integers(0, end))] = int(rng.integers(0, 256))
            data = bytes(b)
            self.stats.corrupted += 1
        delay = f.delay_s + (abs(float(rng.normal(0.0, f.jitter_s))) if f.jitter_s else 0.0)
        if f.reorder and rng.random() < f.reorder:
            delay += self.cycle_s * 1.5
            self.stats.reordered += 1
            self.stats.reordered_seqs.append(seq)
        copies = 1
        if f.duplicate and rng.random() < f.duplicate:
            copies = 2
            self.stats.duplicated += 1
            self.stats.duplicated_seqs.append(seq)
        for _ in range(copies):
            if delay <= 0.0:
                self._sendto(data, addr)
            else:
                self._k += 1
                heapq.heappush(self.queue, (now + delay, self._k, data, addr))
        return True

    def drop_incoming(self) -> bool:
        f = self.f
        if self.active and f.loss and self.rng.random() < f.loss:
            self.stats.dropped_in += 1
            return True
        return False

    def flush(self, now: float) -> None:
        q = self.queue
        while q and q[0][0] <= now:
            _, _, data, addr = heapq.heappop(q)
            self._sendto(data, addr)

    def next_due(self) -> float | None:
        return self.queue[0][0] if self.queue else None

    def _sendto(self, data: bytes, addr: tuple[str, int]) -> None:
        try:
            self.sock.sendto(data, addr)
        except OSError:
            pass  # remote port closed (ICMP) or no route: the KRC keeps sending
