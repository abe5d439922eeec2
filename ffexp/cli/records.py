"""``ffexp analyze``, ``compare``, ``recover`` and ``topics``: working with recordings.

Imports only typer, the standard library and light ffexp modules at module
level; numpy, mcap and matplotlib load inside the commands.
"""

from __future__ import annotations

import sys
from dataclasses import asdict
from pathlib import Path
from typing import Any

import typer

from ffexp.cli._common import cli_errors, fail, new_file
from ffexp.cli.progress import Steps
from ffexp.cli.run import WIDE_HELP

PLOTS_HELP = (
    "Write each run's figures (PNG and SVG) into this directory; existing files are "
    "kept (a taken name gets -1, -2, ...)."
)


def _warn(messages: list[str]) -> None:
    for w in messages:
        print(f"warning: {w}", file=sys.stderr)


def _check_plots_dir(plots: Path | None) -> None:
    from ffexp.errors import ConfigError

    if plots is not None and plots.exists() and not plots.is_dir():
        raise ConfigError("--plots", str(plots), "exists and is not a directory")


@cli_errors
def analyze(
    recordings: list[Path] = typer.Argument(..., help="Run recordings (.mcap)."),
    as_json: bool = typer.Option(
        False, "--json", help="One JSON object per run on stdout (with file and complete)."
    ),
    plots: Path | None = typer.Option(None, "--plots", help=PLOTS_HELP),
) -> None:
    """Metrics of a run from its recording (and the paper's figures with --plots).

    Each run also gets the link's verdict on the trial (valid, or invalid with the
    link faults during ALIGN), and a run that never got a measurement says so.
    """
    from ffexp import figures
    from ffexp.analysis import metrics, run_name
    from ffexp.cli.tables import console, json_line, key_value_table
    from ffexp.hil.analysis import analyze_recording, is_hil
    from ffexp.linkcheck import check_link
    from ffexp.recording import load
    from ffexp.recording.kind import check_run

    _check_plots_dir(plots)
    con = console()
    for path in recordings:
        rec = load(path)
        if is_hil(rec):  # a rendered-target impact (ffexp hil): its own numbers
            values = {"file": str(path), **analyze_recording(rec)}
            if as_json:
                typer.echo(json_line(values))
            else:
                con.print(key_value_table(path.stem, values))
            continue
        check_run(path, rec.metadata)
        link = check_link(rec)
        if not link.measured and "run" in rec.metadata:  # a robot that never answered
            _warn(rec.warnings)
            if as_json:
                typer.echo(json_line({"file": str(path), "run": run_name(rec),
                                      "complete": rec.complete, "measured": False,
                                      "trial_valid": link.trial_valid,
                                      "trial_validity": link.validity,
                                      "link": link.text().removeprefix("link: ")}))
            else:
                con.print(f"{run_name(rec)}: {link.text()}")
            continue
        m = metrics(rec)  # an unusable file fails here, with its one error line
        _warn(rec.warnings)
        values = {"file": str(path), "run": run_name(rec), **asdict(m), "measured": True,
                  "link": link.text().removeprefix("link: ")}
        values.pop("warnings")
        if as_json:
            typer.echo(json_line({**values, "warnings": m.warnings}))
        else:
            con.print(key_value_table(run_name(rec), values))
        if plots is not None:
            with Steps() as steps, steps.step(f"drawing the figures of {path.name}"):
                written = figures.write_run_figures(rec, plots, run_name(rec))
            for fig in written:
                print(f"figure: {fig}", file=sys.stderr if as_json else sys.stdout)


@cli_errors
def compare(
    recordings: list[Path] = typer.Argument(..., help="Run recordings (.mcap)."),
    csv_path: Path | None = typer.Option(
        None, "--csv", help="Also write the table as CSV data (full precision, every column)."
    ),
    as_json: bool = typer.Option(
        False, "--json", help="Print one JSON object per run instead of the table."
    ),
    wide: bool = typer.Option(False, "--wide", help=WIDE_HELP),
) -> None:
    """One table across runs: the paper's Table (res_par) layout plus our metrics.

    A run cut short (a killed run, read up to its last complete chunk) shows
    complete = no.
    """
    from ffexp.analysis import COMPARE_COLUMNS, COMPARE_KEYS, compare_row
    from ffexp.cli.tables import (
        Column,
        compact_runs,
        console,
        fitted_table,
        json_line,
        write_csv,
    )
    from ffexp.recording import load
    from ffexp.recording.kind import check_run

    new_file("--csv", csv_path)
    rows = []
    with Steps() as steps, steps.step("loading recordings", total=len(recordings)) as advance:
        for path in recordings:
            rec = load(path)
            check_run(path, rec.metadata)
            rows.append(_unmeasured_row(rec) or compare_row(rec))
            _warn(rec.warnings)
            advance()
    if as_json:
        for row in rows:
            typer.echo(json_line(row))
    else:
        con = console(wide=wide)
        cols = [Column(t, k, p) for t, k, p in COMPARE_COLUMNS]
        shown, day = compact_runs(rows)
        con.print(fitted_table(con, day or "runs", cols, shown))
    if csv_path is not None:
        write_csv(csv_path, COMPARE_KEYS, rows)
        print(f"wrote {csv_path}", file=sys.stderr if as_json else sys.stdout)


def _unmeasured_row(rec: Any) -> dict[str, Any] | None:
    """The row of a run that never got a measurement (a robot that never answered, a run
    killed before its first cycle), as ``analyze`` says it; ``None`` for any other file
    (which :func:`ffexp.analysis.compare_row` reads, or fails on with its one line)."""
    from ffexp.analysis import COMPARE_KEYS, run_name
    from ffexp.linkcheck import check_link

    link = check_link(rec)
    if link.measured or "run" not in rec.metadata:
        return None
    row: dict[str, Any] = dict.fromkeys(COMPARE_KEYS)
    row.update(file=str(rec.path), run=run_name(rec), complete=rec.complete,
               protocol=rec.metadata["run"].get("protocol"),
               outcome=link.text().removeprefix("link: "), trial_valid=link.trial_valid,
               trial_validity=link.validity)
    return row


@cli_errors
def recover_cmd(
    recording: Path = typer.Argument(..., help="An unfinished recording (killed run)."),
    output: Path | None = typer.Option(
        None, "-o", "--output", help="Default: <name>.recovered.mcap beside the input "
        "(taken: -1, -2, ...). Never overwritten."
    ),
) -> None:
    """Rewrite every complete chunk of an unfinished recording as a valid, indexed file.

    A killed run's file stays what it is once recovered: without the run's end,
    ``analyze`` and ``compare`` show it complete: no, its trial validity unknown.
    Exit code 2 when the file holds no complete message to recover.
    """
    from ffexp.naming import unique_stem
    from ffexp.recording import recover

    if output is not None and output.resolve() != recording.resolve():  # itself: said later
        new_file("--output", output)
    # the default name beside the input: a recovered file there already is kept (-1, -2, ...)
    stem = recording.with_suffix(".recovered").name
    dst = output or recording.with_name(unique_stem(recording.parent, stem, (".mcap",)) + ".mcap")
    result = recover(recording, dst)
    state = "complete file" if result.complete else "unfinished file"
    if result.corrupt_chunks:
        state += (f", corrupt chunk(s) {', '.join(map(str, result.corrupt_chunks))} "
                  "left out")
    line = (
        f"{recording}: {state}; recovered {result.messages} messages on {result.channels} "
        f"channels into {dst}"
    )
    if result.messages == 0:
        dst.unlink(missing_ok=True)
        raise fail(f"{recording}: no complete message to recover ({state}); nothing written")
    typer.echo(line)
    from ffexp.recording import load
    from ffexp.recording.reader import RUN_END_TOPIC

    fixed = load(dst, [RUN_END_TOPIC])
    if not fixed.complete:
        why = "; ".join(w.removeprefix(f"{dst}: ") for w in fixed.warnings)
        typer.echo(f"{dst}: it analyses as complete: no, its trial validity unknown ({why})")


@cli_errors
def topics(
    recording: Path | None = typer.Argument(
        None, help="A recording: what it holds (topics, counts, rates, time span)."
    ),
    fields: bool = typer.Option(False, "--fields", help="Also list every field of each topic."),
    wide: bool = typer.Option(False, "--wide", help=WIDE_HELP),
) -> None:
    """The topics of a run recording: all that ffexp writes, or what FILE holds."""
    from ffexp.cli.tables import Column, console, fitted_table

    con = console(wide=wide)
    if recording is None:
        from ffexp.recording.topics import field_rows, topic_rows

        cols = [Column("topic", "topic"), Column("type", "type", 3, no_wrap=True, left=True),
                Column("encoding", "encoding", 4, left=True),
                Column("rate", "rate", 2, left=True), Column("what", "doc", 1, left=True)]
        con.print(fitted_table(con, "topics of a run recording", cols, topic_rows()))
        if fields:
            fcols = [Column("topic", "topic"), Column("field", "field", no_wrap=True, left=True),
                     Column("type", "type", 2, no_wrap=True, left=True),
                     Column("unit", "unit", 1, no_wrap=True, left=True),
                     Column("what", "doc", 3, left=True)]
            con.print(fitted_table(con, "fields", fcols, field_rows()))
        return
    from ffexp.recording.reader import contents

    summary = contents(recording)
    _warn(summary.warnings)
    cols = [Column("topic", "topic"), Column("messages", "messages"),
            Column("rate [1/s]", "rate_hz"), Column("first [s]", "first_s", 2),
            Column("last [s]", "last_s", 2), Column("type", "schema", 3, no_wrap=True, left=True)]
    state = "complete" if summary.complete else "incomplete (cut)"
    span = f"{summary.span_s:.3f} s" if summary.span_s is not None else "no messages"
    con.print(fitted_table(con, f"{recording}: {state}, {span}", cols, summary.rows))
