"""Shared pieces of the CLI: error handling and common options."""

from __future__ import annotations

import functools
import sys
from collections.abc import Callable
from typing import ParamSpec, TypeVar

import typer

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
