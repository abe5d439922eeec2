"""``ffexp analyze``, ``compare``, ``recover`` and ``topics``: working with recordings."""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import typer
from rich.console import Console
from rich.table import Table

from ffexp.analysis import COMPARE_COLUMNS, compare_rows, metrics, run_info, write_run_figures
from ffexp.cli._common import cli_errors, plain_table
from ffexp.errors import InputError
from ffexp.recording import load, recover
from ffexp.recording.topics import describe

console = Console(width=170)


def compare_table(text_rows: list[list[str]]) -> Table:
    """The runs side by side, in the layout of the paper's Table (res_par)."""
    return plain_table("runs", [title for title, _key in COMPARE_COLUMNS], text_rows)


def _warn(messages: list[str]) -> None:
    for w in messages:
        print(f"warning: {w}", file=sys.stderr)


@cli_errors
def analyze(
    recordings: list[Path] = typer.Argument(..., help="Run recordings (.mcap)."),
    as_json: bool = typer.Option(False, "--json", help="One JSON object per run on stdout."),
    plots: Path | None = typer.Option(None, "--plots", help="Write the run's figures here."),
) -> None:
    """Metrics of a run from its recording (and the paper's figures with --plots)."""
    for path in recordings:
        rec = load(path)
        _warn(rec.warnings)
        m = metrics(rec)
        if as_json:
            typer.echo(m.to_json())
        else:
            _print_metrics(path, m.__dict__)
        if plots is not None:
            name = str(run_info(rec).get("protocol", path.stem))
            for fig in write_run_figures(rec, plots, name):
                print(f"figure: {fig}", file=sys.stderr if as_json else sys.stdout)


def _print_metrics(path: Path, values: dict[str, object]) -> None:
    rows = [(key, _text(value)) for key, value in values.items() if key != "warnings"]
    console.print(plain_table(str(path), ("metric", "value"), rows, header=False))


def _text(v: object) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, list):
        return "[" + ", ".join(_text(x) for x in v) + "]"
    if isinstance(v, dict):
        return ", ".join(f"{k}={_text(x)}" for k, x in v.items())
    return "-" if v is None else str(v)


@cli_errors
def compare(
    recordings: list[Path] = typer.Argument(..., help="Run recordings (.mcap)."),
    csv_path: Path | None = typer.Option(None, "--csv", help="Also write the table as CSV."),
) -> None:
    """One table across runs: the paper's Table (res_par) layout plus our metrics."""
    rows = []
    for path in recordings:
        rec = load(path)
        _warn(rec.warnings)
        rows.append((metrics(rec), run_info(rec)))
    text_rows = compare_rows(rows)
    console.print(compare_table(text_rows))
    if csv_path is not None:
        try:
            with csv_path.open("w", newline="") as fh:
                writer = csv.writer(fh)
                writer.writerow([key for _t, key in COMPARE_COLUMNS])
                writer.writerows(text_rows)
        except OSError as exc:
            raise InputError(f"{csv_path}: cannot write: {exc.strerror}") from None
        typer.echo(f"wrote {csv_path}")


@cli_errors
def recover_cmd(
    recording: Path = typer.Argument(..., help="An unfinished recording (killed run)."),
    output: Path | None = typer.Option(
        None, "-o", "--output", help="Default: <name>.recovered.mcap beside the input."
    ),
) -> None:
    """Rewrite every complete chunk of an unfinished recording as a valid, indexed file."""
    dst = output or recording.with_suffix(".recovered.mcap")
    result = recover(recording, dst)
    state = "complete file" if result.complete else "unfinished file"
    typer.echo(
        f"{recording}: {state}; recovered {result.messages} messages on {result.channels} "
        f"channels into {dst}"
    )


def topics() -> None:
    """List every topic and field of a run recording."""
    typer.echo(describe())
