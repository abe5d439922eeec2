"""What a recording holds once loaded (:class:`Recording`: numpy arrays per CDR topic,
decoded JSON messages, metadata, attachments) and the message layout read from a
schema (:func:`spec_from_schema`). Shared by both ways of reading a file
(:mod:`ffexp.recording.reader`, :mod:`ffexp.recording.columns`); no I/O.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from mcap.records import Schema

from ffexp.errors import InputError
from ffexp.recording.schema import FieldSpec, MessageSpec
from ffexp.recording.topics import CDR_TOPICS

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["JsonData", "Recording", "TopicData", "spec_from_schema"]


@dataclass
class TopicData:
    """One CDR topic: log times and one array per field (first axis = message)."""

    log_time_ns: np.ndarray
    fields: dict[str, np.ndarray]

    def __len__(self) -> int:
        return int(self.log_time_ns.shape[0])

    def __getitem__(self, name: str) -> np.ndarray:
        return self.fields[name]


@dataclass
class JsonData:
    """One JSON topic: log times and the decoded messages."""

    log_time_ns: np.ndarray
    messages: list[dict[str, Any]]

    def __len__(self) -> int:
        return len(self.messages)


@dataclass
class Recording:
    """What :func:`load` returns."""

    path: Path
    topics: dict[str, TopicData] = field(default_factory=dict)
    json: dict[str, JsonData] = field(default_factory=dict)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    attachments: dict[str, bytes] = field(default_factory=dict)
    complete: bool = True
    """False when the file was not finished (read up to its last complete chunk), or when
    a run's recording lacks the run's end (a killed run's file, even once recovered)."""
    warnings: list[str] = field(default_factory=list)

    def topic(self, name: str) -> TopicData:
        """A CDR topic; an :class:`InputError` naming the file if it is absent."""
        try:
            return self.topics[name]
        except KeyError:
            raise InputError(f"{self.path}: no topic {name} in this recording") from None

    @property
    def run_start_ns(self) -> int:
        """Log time of the run's start (run time 0): the first ``/robot/state`` message
        (the first cycle), else the first ``/control/command``, else the earliest
        message loaded, else 0."""
        for name in ("/robot/state", "/control/command"):
            data = self.topics.get(name)
            if data is not None and len(data):
                return int(data.log_time_ns[0])
        firsts = [int(d.log_time_ns[0]) for d in self.topics.values() if len(d)]
        firsts += [int(d.log_time_ns[0]) for d in self.json.values() if len(d)]
        return min(firsts, default=0)

    def frame(self, name: str) -> pd.DataFrame:
        """One topic as a pandas frame: ``t_s`` (seconds from :attr:`run_start_ns`),
        ``log_time_ns`` and one column per field, array fields split into ``name_0 ..
        name_k`` (:mod:`ffexp.recording.frames`)."""
        from ffexp.recording.frames import frame

        return frame(self, name)

    def frames(self) -> dict[str, pd.DataFrame]:
        """Every topic as a frame (:meth:`frame`), by topic name."""
        return {name: self.frame(name) for name in (*self.topics, *self.json)}


_LINE = re.compile(r"^\s*([a-z0-9]+)(?:\[(\d+)\])?\s+([A-Za-z_][A-Za-z0-9_]*)\s*(?:#.*)?$")


def spec_from_schema(schema: Schema) -> MessageSpec | None:
    """A flat fixed-size ros2msg schema as a :class:`MessageSpec`, else None."""
    known = {t.spec.name: t.spec for t in CDR_TOPICS.values()}
    if schema.name in known and schema.data.decode(errors="replace") == known[schema.name].ros2msg:
        return known[schema.name]
    fields = []
    for raw in schema.data.decode(errors="replace").splitlines():
        if not raw.strip() or raw.lstrip().startswith("#"):
            continue
        if raw.startswith("====="):
            return None  # nested message definitions: not a flat message
        m = _LINE.match(raw)
        if m is None:
            return None
        try:
            fields.append(FieldSpec(m.group(3), m.group(1), int(m.group(2) or 1)))
        except ValueError:
            return None
    return MessageSpec(schema.name, tuple(fields)) if fields else None
