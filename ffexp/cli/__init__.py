"""The ``ffexp`` command line (typer).

Each command group lives in its own module and is mounted here; every command
turns user errors into one line on stderr and a non-zero exit
(see :func:`ffexp.cli._common.cli_errors`).
"""

from __future__ import annotations

import typer

from ffexp import __version__
from ffexp.cli import emulate, friction, records, simulate, sweeps
from ffexp.cli import run as run_cli

app = typer.Typer(
    name="ffexp",
    help="Force-control experiments on free-floating objects: simulate, run, record, analyse.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
app.add_typer(simulate.app, name="simulate")
app.add_typer(friction.app, name="friction")
app.command("run")(run_cli.run)
app.command("campaign")(run_cli.campaign)
app.command("analyze")(records.analyze)
app.command("compare")(records.compare)
app.command("recover")(records.recover_cmd)
app.command("topics")(records.topics)
app.command("emulate")(emulate.emulate)
app.command("sweep")(sweeps.sweep)
app.command("limits")(sweeps.limits)
app.command("reproduce")(sweeps.reproduce)


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
    """Force-control experiments on free-floating objects."""


def main() -> None:
    """Console-script entry point."""
    app()
