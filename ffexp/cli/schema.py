"""``ffexp schema``: the JSON Schema of protocol, campaign, sweep, scene, rig, study and impact
files."""

from __future__ import annotations

from pathlib import Path

import typer

from ffexp.cli._common import cli_errors

#: The kinds (ffexp.schemas.KINDS; listed here so that --help needs no import).
KIND_NAMES = ("protocol", "campaign", "sec3-sweep", "scene", "rig", "study", "hil-impact")


@cli_errors
def schema(
    kind: str | None = typer.Argument(
        None, help=f"One of {', '.join(KIND_NAMES)}.", show_default=False
    ),
    write: Path | None = typer.Option(
        None, "--write", help="Write every kind as DIR/<kind>.json (the repository's schemas/)."
    ),
) -> None:
    """Print the JSON Schema of a configuration file kind (from its pydantic model).

    Editors that read Taplo's `#:schema` directive (Even Better TOML) complete
    and check a TOML file whose first line points at it.
    """
    from ffexp.cli._common import fail
    from ffexp.schemas import schema_text, write_all

    if write is not None:
        if kind is not None:
            raise fail("schema: give a KIND or --write DIR, not both")
        for path in write_all(write):
            typer.echo(f"wrote {path}")
        return
    if kind is None:
        raise fail(f"schema: KIND missing; choose one of {', '.join(KIND_NAMES)}")
    typer.echo(schema_text(kind), nl=False)
