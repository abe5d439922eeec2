"""Shared pieces of the CLI: exit codes, error handling, signals.

Imports only the standard library, typer and :mod:`ffexp.errors` at module
level: every command module imports this, and ``ffexp --help`` must stay fast
(no numpy, mujoco, OpenCV, matplotlib, scipy or filterpy; see
``tests/test_fast_start.py``).
"""

from __future__ import annotations

import functools
import math
import os
import signal
import sys
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from types import FrameType
from typing import ParamSpec, TypeVar

import typer

from ffexp.errors import ConfigError, FfexpError

P = ParamSpec("P")
R = TypeVar("R")

# -- exit codes (README "Exit codes"; tests/test_bad_input.py checks them) -------
EXIT_OK = 0
"""The command did what it was asked; a run ended DONE and aligned."""
EXIT_FAILURE = 1
"""A run-time failure the input did not cause: a device, link or simulation error."""
EXIT_BAD_INPUT = 2
"""Bad input: a file, field, address or option (typer's usage errors too)."""
EXIT_ABORTED = 3
"""A run (or a campaign's run) ended ABORT: a safety limit, a lost link, a stop."""
EXIT_TIMED_OUT = 4
"""A run ended DONE at its timeout without aligning."""
EXIT_SIGNAL_BASE = 128
"""128 + N after signal N: 130 Ctrl-C (SIGINT), 143 SIGTERM."""

#: ``--set dotted.key=value``, repeatable, on every command that takes a run protocol.
SET_HELP = ("Override a protocol field, e.g. --set run.timeout_s=2; a scene key as "
            "--set scene.target.lateral=0.012 (repeatable).")
#: ``--scene-set key=value``: a scene key, on every command that runs a simulation.
SCENE_SET_HELP = ("Override a scene key, e.g. --scene-set target.mu=0.006 (repeatable; the "
                  "same as --set scene.target.mu=0.006).")


def with_scene_sets(sets: Sequence[str], scene_sets: Sequence[str]) -> list[str]:
    """``--set`` overrides with each ``--scene-set KEY=VALUE`` as ``scene.KEY=VALUE``;
    a malformed one is a :class:`~ffexp.errors.ConfigError` naming ``--scene-set``."""
    out = list(sets)
    for text in scene_sets:
        key, sep, _value = text.partition("=")
        parts = key.strip().split(".")
        if not sep or not all(parts):
            raise ConfigError("--scene-set", text, "expected scene.key=value, e.g. "
                              "target.mu=0.006")
        if parts[0] == "scene" or (len(parts) == 1 and parts[0] in ("file", "set")):
            raise ConfigError("--scene-set", text, "a key of the scene file itself (e.g. "
                              "target.mu=0.006), without scene.")
        out.append(f"scene.{text.strip()}")
    return out
#: Environment variable that makes an unexpected error print its traceback.
TRACEBACK_ENV = "FFEXP_TRACEBACK"

#: typer settings shared by every command group: ``-h`` is ``--help``.
CONTEXT_SETTINGS = {"help_option_names": ["-h", "--help"]}


def fail(message: str, code: int = EXIT_BAD_INPUT) -> typer.Exit:
    """Print ``error: message`` on stderr and return the Exit to raise."""
    print(f"error: {message}", file=sys.stderr, flush=True)
    return typer.Exit(code)


def cli_errors(func: Callable[P, R]) -> Callable[P, R]:
    """Turn every failure into one line on stderr and a documented exit code.

    :class:`FfexpError`: its message and its ``exit_code``; an ``OSError`` on a
    named file: the file and the reason, exit 2; Ctrl-C: exit 130; anything
    else is a bug: one line naming it, exit 1, and the traceback only when
    ``FFEXP_TRACEBACK=1``.
    """

    @functools.wraps(func)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        try:
            check_numbers(kwargs)
            return func(*args, **kwargs)
        except (typer.Exit, typer.Abort, SystemExit):
            raise
        except FfexpError as exc:
            raise fail(str(exc), exc.exit_code) from None
        except KeyboardInterrupt:
            raise fail("interrupted", EXIT_SIGNAL_BASE + signal.SIGINT) from None
        except OSError as exc:
            if exc.filename is None:
                raise fail(f"{exc.strerror or exc}", EXIT_FAILURE) from None
            raise fail(f"{exc.filename}: {exc.strerror or exc}", EXIT_BAD_INPUT) from None
        except Exception as exc:
            if os.environ.get(TRACEBACK_ENV):
                raise
            raise fail(
                f"internal error ({type(exc).__name__}: {exc}); set {TRACEBACK_ENV}=1 "
                "for the traceback",
                EXIT_FAILURE,
            ) from None

    return wrapper


#: The largest integer an option may give (what fits in 64 bits, as ports, seeds and counts
#: end up in numpy, struct or the OS).
MAX_INT = 2**63 - 1


def _option_name(param: str) -> str:
    """The command line's name of a command's parameter (``set_`` -> ``--set``)."""
    try:  # typer 0.29 carries its own copy of click
        from typer._click.globals import get_current_context
        ctx = get_current_context(silent=True)
    except ImportError:  # pragma: no cover - another typer: the parameter's own name
        ctx = None
    for p in ctx.command.params if ctx is not None else ():
        if p.name == param and p.opts:
            return str(max(p.opts, key=len))
    return "--" + param.rstrip("_").replace("_", "-")


def check_numbers(values: dict[str, object]) -> None:
    """Every number a command got from its command line is finite (``nan``, ``inf``,
    ``1e400`` are errors) and every integer fits in 64 bits: a ConfigError naming the
    option, before the command does anything."""
    from ffexp.errors import ConfigError

    for name, value in values.items():
        items = value if isinstance(value, list | tuple) else (value,)
        for x in items:
            if isinstance(x, float) and not math.isfinite(x):
                raise ConfigError(_option_name(name), str(x), "must be a finite number")
            if isinstance(x, int) and not isinstance(x, bool) and abs(x) > MAX_INT:
                raise ConfigError(_option_name(name), str(x), "is out of range (64 bits)")


#: The most runs one option may ask for (``--seeds``, ``--sample``): more would not end.
MAX_COUNT = 100_000


def count(option: str, value: int | None) -> None:
    """Raise a ConfigError naming ``option`` unless ``value`` is None or 1..MAX_COUNT."""
    from ffexp.errors import ConfigError

    if value is not None and not 1 <= value <= MAX_COUNT:
        raise ConfigError(option, str(value), f"must be 1..{MAX_COUNT}")


def positive(option: str, value: float | None, *, allow_zero: bool = False) -> None:
    """Raise a ConfigError naming ``option`` unless ``value`` is finite and > 0 (>= 0)."""
    from ffexp.errors import ConfigError

    if value is None:
        return
    ok = value >= 0.0 if allow_zero else value > 0.0
    if not (ok and value < float("inf")):
        bound = ">= 0" if allow_zero else "> 0"
        raise ConfigError(option, str(value), f"must be finite and {bound}")


def new_file(option: str, path: Path | None) -> None:
    """Raise a ConfigError naming ``option`` (``""``: an argument, the path alone) when
    ``path``, an output file the user named, is a directory or exists already: nothing
    already written is overwritten.

    Called before the command does its work, so a refused name costs nothing.
    """
    from ffexp.errors import ConfigError

    if path is None:
        return
    where = (option, str(path)) if option else (str(path), "")
    if path.is_dir():
        raise ConfigError(*where, "is a directory, expected a file name")
    if path.exists() or path.is_symlink():
        raise ConfigError(*where, "exists; an output file is never overwritten (give a new "
                          "name)")


def check_scene_file(option: str, path: Path | None) -> None:
    """Raise a ConfigError naming what ``path`` is when a scene option was given another
    kind of ffexp file (a rig, a run protocol): ``is a rig, not a scene``, instead of
    the scene's validation error on the other file's first table (``robot: unknown key``).
    A scene that is merely invalid passes: where it is loaded with the command's
    overrides, its own error names its field (or an override makes it valid)."""
    if path is None:
        return
    from drivers.config import read_toml
    from drivers.description.scene import load_scene
    from ffexp.errors import ConfigError
    from ffexp.filekind import wrong_kind

    try:
        load_scene(path)
    except ConfigError:
        what = wrong_kind(read_toml(path), "scene")
        if what is not None:
            raise ConfigError(option, str(path), what) from None
        # a scene merely invalid (or made valid by the command's overrides): loaded later


def check_cpus(option: str, cpus: list[int] | tuple[int, ...]) -> None:
    """Raise a ConfigError naming ``option`` unless every CPU is one this process may
    run on (the OS refuses the others with a bare "Invalid argument")."""
    from ffexp.errors import ConfigError

    if not cpus or not hasattr(os, "sched_getaffinity"):
        return
    allowed = os.sched_getaffinity(0)
    for cpu in cpus:
        if cpu not in allowed:
            listed = ", ".join(str(c) for c in sorted(allowed))
            raise ConfigError(option, str(cpu), f"not a CPU this process may run on ({listed})")


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
        return None if self.signum is None else EXIT_SIGNAL_BASE + self.signum


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
