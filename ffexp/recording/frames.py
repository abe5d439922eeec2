"""Recordings as tables: one pandas frame per topic (``Recording.frame``, ``ffexp export``).

A CDR topic becomes one row per message and one numeric column per field; an
array field is split into one column per element, ``name_0 .. name_k`` (a 4x4
pose row-major into ``pose_0 .. pose_15``), in the field's own type. A JSON
topic becomes one column per leaf (``pandas.json_normalize``: nested objects as
``timestamp.sec``). Every table starts with ``t_s``, the log time in seconds
from the run start (:attr:`Recording.run_start_ns`), and ``log_time_ns``, the
log time itself. A message field named like one of these two keeps its value
under ``msg_<name>``.

pandas is imported inside the functions: importing this module costs numpy only
(``ffexp --help`` and ``import ffexp`` stay fast).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from drivers.base.types import NS_PER_S

if TYPE_CHECKING:
    import pandas as pd

    from ffexp.recording.reader import JsonData, Recording, TopicData

#: The two time columns every table starts with.
TIME_COLUMNS = ("t_s", "log_time_ns")


def flat_columns(data: TopicData) -> dict[str, np.ndarray]:
    """One 1-D array per column: scalar fields by name, array fields as ``name_k``."""
    out: dict[str, np.ndarray] = {}
    for name, arr in data.fields.items():
        if arr.ndim == 1:
            out[name] = arr
            continue
        flat = arr.reshape(arr.shape[0], -1)
        for k in range(flat.shape[1]):
            out[f"{name}_{k}"] = flat[:, k]
    return out


def seconds(log_time_ns: np.ndarray, start_ns: int) -> np.ndarray:
    """Log times as seconds from ``start_ns`` (integer difference first: no rounding of
    the absolute time)."""
    return (log_time_ns - np.int64(start_ns)).astype(np.float64) / NS_PER_S


def _rename(columns: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    return {(f"msg_{k}" if k in TIME_COLUMNS else k): v for k, v in columns.items()}


def cdr_frame(data: TopicData, start_ns: int) -> pd.DataFrame:
    """A CDR topic as a frame (see the module's description)."""
    import pandas as pd

    cols: dict[str, np.ndarray] = {"t_s": seconds(data.log_time_ns, start_ns),
                                   "log_time_ns": data.log_time_ns}
    cols.update(_rename(flat_columns(data)))
    return pd.DataFrame(cols)


def json_frame(data: JsonData, start_ns: int) -> pd.DataFrame:
    """A JSON topic as a frame: one column per leaf of the messages."""
    import pandas as pd

    body = pd.json_normalize(data.messages) if data.messages else pd.DataFrame()
    body = body.rename(columns={k: f"msg_{k}" for k in TIME_COLUMNS if k in body.columns})
    times = pd.DataFrame({"t_s": seconds(data.log_time_ns, start_ns),
                          "log_time_ns": data.log_time_ns})
    return pd.concat([times, body.reset_index(drop=True)], axis=1)


def frame(rec: Recording, topic: str) -> pd.DataFrame:
    """The frame of one topic of ``rec``; an :class:`InputError` naming the file if it
    has no such topic."""
    from ffexp.errors import InputError

    start = rec.run_start_ns
    if topic in rec.topics:
        return cdr_frame(rec.topics[topic], start)
    if topic in rec.json:
        return json_frame(rec.json[topic], start)
    have = ", ".join(sorted([*rec.topics, *rec.json])) or "none"
    raise InputError(f"{rec.path}: no topic {topic} in this recording (topics: {have})")
