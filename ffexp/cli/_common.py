"""Shared pieces of the CLI: error handling and common options."""

from __future__ import annotations

import functools
import signal
import sys
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from types import FrameType
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


class StopFlag:
    """Set by SIGINT/SIGTERM (see :func:`stop_signals`); a loop polls it and stops safely.

    A second signal raises KeyboardInterrupt: the user gave up waiting.
    """

    def __init__(self) -> None:
        self.signum: int | None = None

    def __call__(self) -> bool:
        return self.signum is not None

    def handle(self, signum: int, _frame: FrameType | None) -> None:
        if self.signum is not None:
            raise KeyboardInterrupt
        self.signum = signum

    def exit_code(self) -> int | None:
        """128 + the signal's number once one came (the shell's convention), else None."""
        return None if self.signum is None else 128 + self.signum


@contextmanager
def stop_signals(flag: StopFlag) -> Iterator[StopFlag]:
    """SIGINT and SIGTERM set ``flag`` inside the block; the old handlers come back after."""
    old = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    for s in old:
        signal.signal(s, flag.handle)
    try:
        yield flag
    finally:
        for s, h in old.items():
            signal.signal(s, h)
