"""Recordings in and out: replay through a controller, diff, export.

Light at module level (typer and the standard library only); each command
imports what it needs inside. ``COMMANDS`` lists ``(name, function)`` pairs
that :mod:`ffexp.cli` mounts as top-level commands.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import typer

from ffexp.cli._common import EXIT_FAILURE, cli_errors, new_file

#: A replay simulates no scene (it feeds the recorded measurements): protocol fields only.
REPLAY_SET_HELP = ("Override a field of the protocol, e.g. --set run.timeout_s=2 (repeatable; "
                   "the replay simulates no scene).")
TOL_HELP = "|A-B| > max(atol, rtol max(|A|,|B|)) is a difference"


def _warn(messages: list[str]) -> None:
    for w in messages:
        print(f"warning: {w}", file=sys.stderr)


@cli_errors
def replay(
    recording: Path = typer.Argument(..., help="The run recording (.mcap) to replay."),
    out: Path = typer.Option(..., "--out", help="The replay's recording (.mcap) to write."),
    protocol: Path | None = typer.Option(
        None, "--protocol", help="Run protocol TOML (default: the one recorded in the run)."
    ),
    overrides: list[str] = typer.Option([], "--set", help=REPLAY_SET_HELP),
) -> None:
    """Feed a run's recorded measurements, open loop, through the estimator, safety
    checks and controller of a protocol; record what it would have commanded and why.

    Open loop: valid only until the replayed commands differ from the recorded ones
    (the measurements answered the recorded commands); the first such cycle is
    reported. Exit 0 when the replay ran, 2 on bad input.
    """
    from ffexp.errors import InputError
    from ffexp.recording.kind import check_run_recording
    from ffexp.recording.reader import check_file
    from ffexp.replay import OPEN_LOOP
    from ffexp.replay import replay as run_replay

    check_file(recording)
    check_run_recording(recording)
    if out.suffix != ".mcap":
        raise InputError(f"{out}: --out must be an .mcap file")
    if out.resolve() != recording.resolve():  # itself: said more precisely by the replay
        new_file("--out", out)
    result = run_replay(recording, out, protocol_path=protocol, overrides=overrides)
    _warn(result.warnings)
    how = f" with --set {' '.join(overrides)}" if overrides else ""
    typer.echo(f"replayed {result.cycles} of {result.recorded_cycles} cycles of {recording.name} "
               f"through {protocol or 'the recorded protocol'}{how}")
    typer.echo(f"note: {OPEN_LOOP}")
    if result.divergence is None:
        typer.echo(f"commands: the recorded ones on every compared cycle (largest difference "
                   f"{result.max_command_diff:.3g})")
    else:
        typer.echo(f"{result.divergence.line()} ({result.diverging_cycles} cycles "
                   f"differ, largest difference {result.max_command_diff:.3g})")
    typer.echo(f"replayed run: {result.verdict}")
    typer.echo(f"recording: {result.path}")


@cli_errors
def diff(
    a: Path = typer.Argument(..., help="Recording A (.mcap)."),
    b: Path = typer.Argument(..., help="Recording B (.mcap)."),
    topics: list[str] = typer.Option(
        [], "--topic", help="Compare only this topic (repeatable; default: every numeric "
        "topic both have)."
    ),
    rtol: float = typer.Option(1e-9, "--rtol", help=f"Relative tolerance ({TOL_HELP})."),
    atol: float = typer.Option(1e-9, "--atol", help=f"Absolute tolerance ({TOL_HELP})."),
    plots: Path | None = typer.Option(
        None, "--plots", help="Write a figure of the differing fields into this directory "
        "(when they differ; none without --plots)."
    ),
) -> None:
    """Per topic and field: the largest difference and where it first exceeds the
    tolerance, aligned by run time from each run's start; with --plots, a figure of what
    differs.

    Columns: max |A-B| and its run time, "from": where it first exceeds the
    tolerance, "beyond": messages beyond it, "paired": A's messages compared.

    Exit 0 when everything compared is within tolerance, 1 when not, 2 on bad input
    (also two recordings without a numeric topic in common: nothing compared).
    """
    from ffexp.cli.tables import console
    from ffexp.diff import check_tolerance, figure
    from ffexp.diff import diff as run_diff
    from ffexp.errors import ConfigError
    from ffexp.recording import load

    check_tolerance("--rtol", rtol)
    check_tolerance("--atol", atol)
    if plots is not None and plots.exists() and not plots.is_dir():
        raise ConfigError("--plots", str(plots), "exists and is not a directory")
    ra, rb = load(a), load(b)
    _warn(ra.warnings + rb.warnings)
    result = run_diff(ra, rb, topics, rtol=rtol, atol=atol)
    if not result.topics:  # "within tolerance on 0 topics" would say they agree
        raise ConfigError(f"{a}, {b}", "", "no numeric topic in both recordings: nothing "
                          "to compare")
    con = console()
    con.print(_diff_table(result), soft_wrap=True)
    for name, only in ((a, result.only_a), (b, result.only_b)):
        if only and not topics:
            typer.echo(f"only in {name.name} (not compared): {', '.join(only)}")
    first = result.first
    if result.ok:
        typer.echo(f"within tolerance (rtol {rtol:g}, atol {atol:g}) on "
                   f"{len(result.topics)} topics")
        return
    if first is not None:
        typer.echo(f"first difference: {first.topic} {first.column} at {first.first_s:.3f} s")
    written = [] if plots is None else figure(result, ra, rb, plots,
                                              f"diff-{a.stem}-vs-{b.stem}")
    for path in written:
        typer.echo(f"figure: {path}")
    raise typer.Exit(EXIT_FAILURE)


def _diff_table(result: Any) -> Any:
    from rich.table import Table

    table = Table(title=f"{result.a.name} vs {result.b.name}", title_justify="left")
    table.add_column("topic", no_wrap=True)
    table.add_column("field", no_wrap=True)
    for col in ("max |A-B|", "at [s]", "from [s]", "beyond", "paired"):
        table.add_column(col, justify="right")
    for t in result.topics:
        paired = f"{t.paired}/{t.n_a}"
        if t.note and not t.fields:
            table.add_row(t.topic, t.note, "", "", "", "", paired)
        if t.ok:
            table.add_row(t.topic, "all within", f"{t.max_abs:.3g}", "", "", "", paired)
        for f in t.fields:
            table.add_row(t.topic, f.column, f"{f.max_abs:.3g}", f"{f.at_s:.3f}",
                          f"{f.first_s:.3f}", str(f.count), paired)
    return table


@cli_errors
def export(
    recording: Path = typer.Argument(..., help="The run recording (.mcap)."),
    fmt: str = typer.Option("parquet", "--format", help="parquet or csv."),
    topics: list[str] = typer.Option(
        [], "--topic", help="Export only this topic (repeatable; default: every topic)."
    ),
    out: Path | None = typer.Option(
        None, "--out", help="Directory for the tables (default: <run>-tables beside it)."
    ),
) -> None:
    """One table per topic (numeric columns, arrays split into name_0..name_k, t_s in
    seconds from the run start), as Parquet or CSV. Exit 0, or 2 on bad input."""
    from ffexp.errors import ConfigError
    from ffexp.export import FORMATS, SUMMARY_TOPICS, default_dir
    from ffexp.export import export as run_export
    from ffexp.recording import load

    if fmt not in FORMATS:
        raise ConfigError("--format", fmt, f"choose one of {', '.join(FORMATS)}")
    # the first cycle's topics too: t_s counts from the run start whatever is exported;
    # and what says whether the run's end is recorded, and the trial's validity
    wanted = [*topics, *SUMMARY_TOPICS, "/control/command"] if topics else None
    rec = load(recording, wanted)
    _warn(rec.warnings)
    for path in run_export(rec, fmt, out or default_dir(recording), topics):
        typer.echo(str(path))


COMMANDS: list[tuple[str, Callable[..., Any]]] = [
    ("replay", replay), ("diff", diff), ("export", export),
]
