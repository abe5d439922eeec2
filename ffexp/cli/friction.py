"""``ffexp friction``: residual friction of the air bed from video."""

from __future__ import annotations

import typer

app = typer.Typer(
    help="Residual friction of the air-bed target from video.",
    no_args_is_help=True,
)
