"""The results table: one row per run, typed columns, CSV and Parquet (pandas, pyarrow).

Columns: ``run_id``, ``target`` (the protocol or the paper run), ``rig`` (the rig
file, or ``<built-in DRIVER rig>``), the varied
keys, ``seed``, every metric of ``ffexp analyze --json`` (six-vectors one
column per axis, the link summary ``link_*``), ``error``, ``wall_s``,
``path`` (relative to the sweep directory) and ``recording`` (``full`` or ``lean``:
what the run's file holds, :mod:`ffexp.sweeps.worker`). Numbers are numeric columns
(missing: NaN), flags boolean, the rest text.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import pandas as pd

#: Columns that come last, in this order.
TAIL = ("error", "wall_s", "path", "recording")
#: Text columns (an all-missing column of any other name is numeric: NaN).
TEXT_COLUMNS = frozenset({
    "run_id", "target", "rig", "protocol", "method", "break_times_s", "aborted", "warnings",
    "error", "outcome", "outcome_note",
    "path", "recording",
})
CSV_NAME = "results.csv"
PARQUET_NAME = "results.parquet"


def frame(rows: Sequence[dict[str, Any]]) -> pd.DataFrame:
    """The rows as a typed DataFrame (columns in first-seen order, TAIL last)."""
    import pandas as pd

    order: list[str] = []
    for row in rows:
        order.extend(k for k in row if k not in order and k not in TAIL)
    order.extend(TAIL)
    data: dict[str, Any] = {}
    for col in order:
        values = [row.get(col) for row in rows]
        present = [v for v in values if v is not None]
        if not present and col not in TEXT_COLUMNS:
            data[col] = pd.array([float("nan")] * len(values), dtype="float64")
        elif present and all(isinstance(v, bool) for v in present):
            data[col] = pd.array(values, dtype="boolean")
        elif present and all(isinstance(v, int | float) and not isinstance(v, bool)
                             for v in present):
            if all(isinstance(v, int) for v in present) and len(present) == len(values):
                data[col] = pd.array(values, dtype="int64")
            else:
                data[col] = pd.array([float("nan") if v is None else float(v) for v in values],
                                     dtype="float64")
        else:
            data[col] = pd.array([None if v is None else str(v) for v in values],
                                 dtype="string")
    return pd.DataFrame(data, columns=order)


def write(df: pd.DataFrame, out_dir: Path) -> list[Path]:
    """``results.csv`` and ``results.parquet`` in ``out_dir`` (each written to a temporary
    name and renamed: a reader never sees half a table)."""
    paths = []
    for name in (CSV_NAME, PARQUET_NAME):
        final = out_dir / name
        tmp = out_dir / f".{name}.tmp"
        if name == CSV_NAME:
            df.to_csv(tmp, index=False)
        else:
            df.to_parquet(tmp, index=False)
        tmp.replace(final)
        paths.append(final)
    return paths


def recordings_note(rows: Sequence[dict[str, Any]]) -> str:
    """What the runs' files hold, in words: ``lean recordings``, ``full recordings``, or
    how many of each (a lean study keeps full runs it found done before)."""
    lean = sum(1 for r in rows if r.get("recording") == "lean")
    if lean == len(rows):
        return "lean recordings"
    if not lean:
        return "full recordings"
    return f"{lean} lean and {len(rows) - lean} full recordings"


def without_wall_time(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Rows without ``wall_s`` (what must agree between two executors)."""
    return [{k: v for k, v in row.items() if k != "wall_s"} for row in rows]
