"""Tables for people (rich, fitted to the terminal) and for programs (CSV, JSON).

A people's table keeps its columns in their order but drops the
lowest-priority ones until rich can lay it out within the console's width
(80 columns when stdout is not a terminal); ``--wide`` keeps all of them.
Machine output is data: numbers at full precision, empty cells (CSV) or
``null`` (JSON) for missing values.
"""

from __future__ import annotations

import csv
import json
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ffexp.errors import InputError

if TYPE_CHECKING:
    from rich.console import Console
    from rich.table import Table

#: Width of the console with ``--wide`` (a table is never folded then).
WIDE = 400
#: A text column is folded to no less than this many characters.
TEXT_WIDTH = 24


@dataclass(frozen=True)
class Column:
    """One column: its title, the key of its value, its priority (0 = always shown)."""

    title: str
    key: str
    priority: int = 0
    digits: int = 3
    no_wrap: bool = False
    """Never fold the cells (names, topics): other columns give way first."""
    left: bool = False
    """Left-justified (text); numbers are right-justified."""


def console(*, wide: bool = False, stderr: bool = False) -> Console:
    """The console a command prints its tables on."""
    from rich.console import Console

    return Console(width=WIDE if wide else None, stderr=stderr, highlight=False)


def text(value: object, digits: int = 3) -> str:
    """A value for people: ``digits`` significant digits, ``-`` for missing."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    if isinstance(value, list | tuple):
        return "[" + ", ".join(text(x, digits) for x in value) + "]"
    if isinstance(value, Mapping):
        return ", ".join(f"{k}={text(x, digits)}" for k, x in value.items())
    return str(value)


def _build(title: str, columns: Sequence[Column], rows: Sequence[Mapping[str, Any]]) -> Table:
    from rich.table import Table
    from rich.text import Text

    table = Table(title=Text(title), title_justify="left")
    for i, col in enumerate(columns):
        # rich would read unit brackets such as "[s]" as markup: Text keeps them
        table.add_column(
            Text(col.title), justify="left" if i == 0 or col.left else "right",
            no_wrap=col.no_wrap or i == 0,
        )
    for row in rows:
        table.add_row(*(Text(text(row.get(c.key), c.digits)) for c in columns))
    return table


def needed_width(col: Column, rows: Sequence[Mapping[str, Any]]) -> int:
    """The width a column needs to read well: numbers and names whole, text
    folded at most to :data:`TEXT_WIDTH` characters (the header may fold)."""
    cells = [text(r.get(col.key), col.digits) for r in rows]
    longest = max((len(c) for c in cells), default=0)
    if col.left and not col.no_wrap:
        longest = min(longest, TEXT_WIDTH)
    header = max(len(w) for w in col.title.split()) if col.title.strip() else 0
    return max(longest, header) + 3  # padding and the border


def fitted_table(
    con: Console, title: str, columns: Sequence[Column], rows: Sequence[Mapping[str, Any]]
) -> Table:
    """The table with as many columns as fit ``con``'s width, by priority.

    Columns are dropped, highest priority number first, while their needed
    widths (:func:`needed_width`) add up to more than the console; the title
    says how many were left out (``--wide`` shows them).
    """
    keep = list(columns)
    by_priority = sorted((c for c in columns if c.priority > 0), key=lambda c: -c.priority)
    for col in by_priority:
        if sum(needed_width(c, rows) for c in keep) + 1 <= con.width:
            break
        keep.remove(col)
    dropped = len(columns) - len(keep)
    if dropped:
        title = f"{title} ({dropped} columns left out; --wide shows all)"
    return _build(title, keep, rows)


_DATE = re.compile(r"-(\d{8})-(\d{6})(-\d+)?$")


def compact_runs(
    rows: Sequence[Mapping[str, Any]], key: str = "run"
) -> tuple[list[dict[str, Any]], str]:
    """Rows whose run names drop the date when every run is of the same UTC day
    (``method2-base-20261123-190102`` shows as ``method2-base-190102``), and a
    note for the title naming that day ("" if nothing was dropped)."""
    dates = {m.group(1) for r in rows if (m := _DATE.search(str(r.get(key, ""))))}
    if len(dates) != 1 or not all(_DATE.search(str(r.get(key, ""))) for r in rows):
        return [dict(r) for r in rows], ""
    out = []
    for r in rows:
        row = dict(r)
        row[key] = _DATE.sub(lambda m: f"-{m.group(2)}{m.group(3) or ''}", str(r[key]))
        out.append(row)
    (day,) = dates
    return out, f"runs of {day[:4]}-{day[4:6]}-{day[6:]} UTC"


def key_value_table(title: str, values: Mapping[str, Any]) -> Table:
    """A two-column table of one record's values (``ffexp analyze``)."""
    from rich.table import Table
    from rich.text import Text

    table = Table(title=Text(title), title_justify="left", show_header=False)
    table.add_column("metric", no_wrap=True)
    table.add_column("value", overflow="fold")
    for key, value in values.items():
        table.add_row(Text(key), Text(text(value, 4)))
    return table


def _cell(value: object) -> object:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    if isinstance(value, list | tuple | dict):
        return json.dumps(value)
    return value


def write_csv(path: Path, keys: Sequence[str], rows: Sequence[Mapping[str, Any]]) -> None:
    """Rows as CSV: full precision (``repr`` of floats), empty cells for missing values.

    Raises:
        InputError: ``path`` cannot be written.
    """
    try:
        with path.open("w", newline="") as fh:
            writer = csv.writer(fh)
            writer.writerow(keys)
            for row in rows:
                writer.writerow([_cell(row.get(k)) for k in keys])
    except OSError as exc:
        raise InputError(f"{path}: cannot write: {exc.strerror}") from None


def json_line(row: Mapping[str, Any]) -> str:
    """One JSON object (NaN as null, numpy scalars as numbers)."""

    def default(x: object) -> object:
        item = getattr(x, "item", None)
        if callable(item):
            return item()
        raise TypeError(type(x).__name__)

    clean = {
        k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in row.items()
    }
    return json.dumps(clean, allow_nan=False, default=default)
