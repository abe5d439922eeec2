"""``ffexp report DIR``: one self-contained HTML page for a campaign or sweep directory."""

from __future__ import annotations

from pathlib import Path

import typer

from ffexp.cli._common import cli_errors, new_file
from ffexp.cli.progress import Steps


@cli_errors
def report(
    directory: Path = typer.Argument(..., help="A campaign or sweep directory."),
    out: Path | None = typer.Option(
        None, "--out", "-o", help="The HTML file (default: DIR/report-<time>.html); an "
        "existing file is never overwritten."
    ),
) -> None:
    """Write one HTML page (images embedded) for a campaign or sweep: the paper's table
    beside ours, the summary tables, the figures, versions, source revision, protocols."""
    from ffexp.report import write_report

    new_file("--out", out)
    with Steps() as steps, steps.step(f"report of {directory}"):
        path = write_report(directory, out)
    typer.echo(f"report: {path}")
