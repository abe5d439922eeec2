"""Counting what happened to received datagrams, shared by the wire codecs."""

from __future__ import annotations

from enum import IntEnum
from typing import ClassVar, Generic, TypeVar

S = TypeVar("S", bound=IntEnum)


class OutcomeCounts(Generic[S]):
    """Counts per outcome of an ``IntEnum`` whose member 0 means accepted.

    Subclasses name their enum in :attr:`outcomes`.
    """

    __slots__ = ("counts",)
    outcomes: ClassVar[type[IntEnum]]

    def __init__(self) -> None:
        self.counts: list[int] = [0] * len(self.outcomes)

    def add(self, status: S) -> None:
        """Count one datagram with outcome ``status``."""
        self.counts[status] += 1

    def __getitem__(self, status: S) -> int:
        return self.counts[status]

    @property
    def ok(self) -> int:
        """Datagrams accepted (outcome 0)."""
        return self.counts[0]

    @property
    def total(self) -> int:
        """Datagrams seen."""
        return sum(self.counts)

    @property
    def rejected(self) -> int:
        """Datagrams rejected for any reason."""
        return self.total - self.ok

    def as_dict(self) -> dict[str, int]:
        """``{"ok": n, "too_short": n, ...}`` for logs."""
        return {s.name.lower(): self.counts[s] for s in self.outcomes}

    def reset(self) -> None:
        """Set every count to zero."""
        self.counts[:] = [0] * len(self.outcomes)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.as_dict()})"
