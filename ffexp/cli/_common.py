"""Shared pieces of the CLI: error handling and common options."""

from __future__ import annotations

import functools
import sys
from collections.abc import Callable, Iterable, Sequence
from typing import ParamSpec, TypeVar

import typer
from rich.table import Table
from rich.text import Text

from ffexp.errors import FfexpError

P = ParamSpec("P")
R = TypeVar("R")

#: ``--set dotted.key=value``, repeatable, on every command that takes a protocol.
SET_HELP = "Override a protocol field, e.g. --set sweep.values=[1,2] (repeatable)."


def cli_errors(func: Callable[P, R]) -> Callable[P, R]:
    """Turn any :class:`FfexpError` into one line on stderr and its exit code."""

    @functools.wraps(func)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        try:
            return func(*args, **kwargs)
        except FfexpError as exc:
            print(f"error: {exc}", file=sys.stderr)
            raise typer.Exit(exc.exit_code) from None
        except KeyboardInterrupt:
            print("error: interrupted", file=sys.stderr)
            raise typer.Exit(130) from None

    return wrapper


def plain_table(
    title: str, columns: Sequence[str], rows: Iterable[Sequence[str]], *, header: bool = True
) -> Table:
    """A rich table whose texts are shown as they are: unit brackets such as
    ``[s]`` or ``[m/s]`` would otherwise be taken for rich markup and vanish."""
    table = Table(title=Text(title), show_header=header)
    for i, col in enumerate(columns):
        table.add_column(Text(col), justify="left" if i == 0 and not header else "right")
    for row in rows:
        table.add_row(*(Text(cell) for cell in row))
    return table
