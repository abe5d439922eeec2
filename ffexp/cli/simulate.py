"""``ffexp simulate``: the paper's Section III model and its sweeps."""

from __future__ import annotations

import typer

app = typer.Typer(
    help="Simulations of the paper's Section III contact model.",
    no_args_is_help=True,
)
