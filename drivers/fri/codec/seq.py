"""FRI 1.x uint16 sequence counters (``sendSeqCount`` / ``reflSeqCount``): next, delta, events.

Part of the codec (re-exported by :mod:`drivers.fri.codec`); pure functions.
"""

from __future__ import annotations

from enum import IntEnum
from typing import Final

# --------------------------------------------------------------------------- sequence counters

SEQ_MODULUS: Final = 0x10000


def seq_next(seq: int) -> int:
    """The counter value after ``seq``: 65535 is followed by 0."""
    return (int(seq) + 1) & 0xFFFF


def seq_delta(new: int, old: int) -> int:
    """Wrapped difference ``new - old`` of two uint16 counters, in ``[-32768, 32767]``.

    1 means "the next one", 0 a duplicate, ``k > 1`` that ``k - 1`` were
    skipped, a negative value that ``new`` is older than ``old`` (reordered).
    """
    return ((int(new) - int(old) + 0x8000) & 0xFFFF) - 0x8000


class SeqEvent(IntEnum):
    """How a received counter relates to the last accepted one."""

    NEXT = 0
    DUPLICATE = 1
    GAP = 2
    STALE = 3


def classify_seq(new: int, last: int) -> tuple[SeqEvent, int]:
    """Classify ``new`` against ``last``; return the event and :func:`seq_delta`.

    For :attr:`SeqEvent.GAP` ``delta - 1`` packets are missing; for
    :attr:`SeqEvent.STALE` the packet is ``-delta`` steps older than ``last``.
    """
    d = seq_delta(new, last)
    if d == 1:
        return SeqEvent.NEXT, d
    if d == 0:
        return SeqEvent.DUPLICATE, d
    if d > 1:
        return SeqEvent.GAP, d
    return SeqEvent.STALE, d
