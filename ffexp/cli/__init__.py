"""The ``ffexp`` command line (typer).

Each command group lives in its own module and is mounted here; every command
turns user errors into one line on stderr and a documented exit code (see
:mod:`ffexp.cli._common`). This module and the command modules import only
typer, the standard library and light ffexp modules at module level: the
simulator, numpy-heavy analysis, OpenCV and matplotlib load inside the
commands, so ``ffexp --help`` and argument errors answer at once
(``tests/test_fast_start.py``).
"""

from __future__ import annotations

import sys
from typing import Any

import typer
from typer.core import TyperGroup

try:  # typer 0.29 carries its own copy of click
    from typer._click.exceptions import ClickException, NoArgsIsHelpError, UsageError
except ImportError:  # pragma: no cover - a typer on the installed click
    from click.exceptions import (  # type: ignore[assignment]
        ClickException,
        NoArgsIsHelpError,
        UsageError,
    )

from ffexp import __version__
from ffexp.cli import calibrate as calibrate_cli
from ffexp.cli import check as check_cli
from ffexp.cli import data, emulate, friction, records, report, schema, simulate, sweeps, tracker
from ffexp.cli import hil as hil_cli
from ffexp.cli import run as run_cli
from ffexp.cli._common import CONTEXT_SETTINGS, EXIT_BAD_INPUT


class OneLineErrors(TyperGroup):
    """typer's group whose usage errors (a missing argument, an unknown option, a
    value of the wrong type) are one line, ``error: ffexp run: ...``, exit 2."""

    def main(  # type: ignore[override]
        self, args: Any = None, prog_name: str | None = None, complete_var: str | None = None,
        standalone_mode: bool = True, **extra: Any,
    ) -> Any:
        try:
            rv = super().main(
                args=args, prog_name=prog_name, complete_var=complete_var,
                standalone_mode=False, **extra,
            )
        except NoArgsIsHelpError as exc:
            if not standalone_mode:
                raise
            exc.show()
            sys.exit(exc.exit_code)
        except ClickException as exc:
            where = exc.ctx.command_path if isinstance(exc, UsageError) and exc.ctx else ""
            hint = f" ({where} -h for help)" if where else ""
            prefix = f"{where}: " if where else ""
            print(f"error: {prefix}{exc.format_message()}{hint}", file=sys.stderr, flush=True)
            code = exc.exit_code if exc.exit_code else EXIT_BAD_INPUT
            if not standalone_mode:
                raise
            sys.exit(code)
        except typer.Abort:
            print("error: aborted", file=sys.stderr, flush=True)
            if not standalone_mode:
                raise
            sys.exit(1)
        if not standalone_mode:
            return rv
        sys.exit(rv if isinstance(rv, int) else 0)

app = typer.Typer(
    name="ffexp",
    cls=OneLineErrors,
    help="Force-control experiments on free-floating objects: simulate, run, record, analyse.",
    no_args_is_help=True,
    add_completion=True,
    pretty_exceptions_enable=False,
    context_settings=CONTEXT_SETTINGS,
    epilog="Exit codes: 0 ok (a run aligned), 1 device or simulation failure, 2 bad input, "
    "3 a run aborted, 4 a run timed out without aligning, 128+N on signal N.",
)
app.add_typer(simulate.app, name="simulate")
app.add_typer(friction.app, name="friction")
app.command("run")(run_cli.run)
app.command("campaign")(run_cli.campaign)
app.command("check")(check_cli.check)
app.command("analyze")(records.analyze)
app.command("compare")(records.compare)
app.command("recover")(records.recover_cmd)
app.command("topics")(records.topics)
app.command("report")(report.report)
app.command("schema")(schema.schema)
app.command("emulate")(emulate.emulate)
app.command("sweep")(sweeps.sweep)
app.command("limits")(sweeps.limits)
app.command("reproduce")(sweeps.reproduce)
app.command("calibrate")(calibrate_cli.calibrate)
app.command("resimulate")(calibrate_cli.resimulate)
app.command("hil")(hil_cli.hil)
app.command("hil-sweep")(hil_cli.hil_sweep)
for _module in (data, tracker):  # command modules that list their commands
    for _name, _command in _module.COMMANDS:
        app.command(_name)(_command)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"ffexp {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(
        False, "--version", callback=_version, is_eager=True, help="Print the version and exit."
    ),
) -> None:
    """Force-control experiments on free-floating objects.

    Exit codes: 0 ok (a run aligned), 1 a device or simulation failure,
    2 bad input, 3 a run aborted, 4 a run timed out without aligning,
    128+N on signal N (130 Ctrl-C, 143 SIGTERM).
    """


def main() -> None:
    """Console-script entry point (also ``python -m ffexp``: the program is named ffexp)."""
    app(prog_name="ffexp")
