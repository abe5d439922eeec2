"""``ffexp sweep``, ``ffexp limits`` and ``ffexp reproduce``: many runs of one protocol.

Heavy imports (the simulator, pandas, matplotlib, ray) happen inside the
commands, never at module import (``ffexp --help`` must stay fast).
"""

from __future__ import annotations

from pathlib import Path

import typer


def sweep(
    protocol: Path = typer.Argument(..., help="Run protocol (TOML)."),
) -> None:
    """Run a protocol over a grid or a sample of parameter values (being built)."""
    typer.echo("error: ffexp sweep is not available yet", err=True)
    raise typer.Exit(2)


def limits(
    protocol: Path = typer.Argument(..., help="Run protocol (TOML)."),
) -> None:
    """Find the lower and upper limit of a gain between aligning and not (being built)."""
    typer.echo("error: ffexp limits is not available yet", err=True)
    raise typer.Exit(2)


def reproduce() -> None:
    """Check the paper's claims over the uncertain rig parameters (being built)."""
    typer.echo("error: ffexp reproduce is not available yet", err=True)
    raise typer.Exit(2)
