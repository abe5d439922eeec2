"""``ffexp sweep``, ``ffexp limits`` and ``ffexp reproduce``: many runs of one protocol.

Heavy imports (the simulator, pandas, matplotlib, ray) happen inside the
commands, never at module import (``ffexp --help`` must stay fast). The
engine is :mod:`ffexp.sweeps` (docs/sweeps.md).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from ffexp.cli._common import SET_HELP, StopFlag, cli_errors, stop_signals

if TYPE_CHECKING:
    from ffexp.sweeps.engine import Runner
    from ffexp.sweeps.executors import ExecutorSpec
    from ffexp.sweeps.session import Display

EXECUTOR_HELP = (
    "local[:WORKERS] (a process pool; default all CPUs), or Ray: ray | ray:auto (the running "
    "cluster), ray:HOST:PORT, ray://HOST:PORT (client), ray:local (start one here)."
)
OUT_HELP = (
    "Sweep directory (runs, results.csv/.parquet, figures). Runs already in it are not run "
    "again. With Ray it must be a path every worker sees (shared storage)."
)
SEEDS_HELP = "Noise seeds per point: the protocol's seed and the next N-1."


def _check_out(out: Path) -> None:
    from ffexp.errors import ConfigError

    if out.exists() and not out.is_dir():
        raise ConfigError("--out", str(out), "exists and is not a directory")


@contextmanager
def _session(out: Path, spec: ExecutorSpec, label: str) -> Iterator[tuple[Runner, Display]]:
    from ffexp.sweeps.engine import Stopped
    from ffexp.sweeps.session import session

    with stop_signals(StopFlag()) as flag:
        try:
            with session(out, spec, label, flag) as (runner, display):
                yield runner, display
        except Stopped:
            pass
        code = flag.exit_code()
        if code is not None:
            typer.echo(f"{label}: stopped; finished runs are kept in {out} (run the same "
                       "command again to go on)", err=True)
            raise typer.Exit(code)


def _summary_rows(rows: Sequence[dict[str, Any]], keys: Sequence[str]) -> list[dict[str, Any]]:
    """Per point (over seeds): aligned fraction, mean breaks, mean f_z, failed runs."""
    groups: dict[tuple[Any, ...], list[dict[str, Any]]] = {}
    for row in rows:
        groups.setdefault(tuple(row.get(k) for k in keys), []).append(row)
    out = []
    for point, group in groups.items():
        ok = [r for r in group if not r.get("error")]
        fz = [r["mean_fz_align_n"] for r in ok if r.get("mean_fz_align_n") is not None]
        out.append({
            **dict(zip(keys, point, strict=True)),
            "runs": len(group),
            "aligned": sum(bool(r.get("aligned")) for r in ok) / len(ok) if ok else None,
            "breaks": sum(int(r.get("contact_breaks") or 0) for r in ok) / len(ok) if ok
            else None,
            "fz": sum(fz) / len(fz) if fz else None,
            "failed": len(group) - len(ok),
        })
    return out


def _print_summary(title: str, rows: Sequence[dict[str, Any]], keys: Sequence[str]) -> None:
    from ffexp.cli.tables import Column, console, fitted_table

    con = console()
    cols = [Column(k, k) for k in keys] + [
        Column("runs", "runs", 2), Column("aligned", "aligned"), Column("breaks", "breaks", 1),
        Column("mean f_z ALIGN [N]", "fz", 1), Column("failed", "failed"),
    ]
    con.print(fitted_table(con, title, cols, _summary_rows(rows, keys)))


@cli_errors
def sweep(
    protocol: Path = typer.Argument(..., help="Run protocol (TOML)."),
    vary: list[str] = typer.Option(
        [], "--vary", help="KEY=V1,V2,... (repeatable; the full grid). KEY is any protocol "
        "key, scene keys as scene.target.lateral, list elements as align.k_ri[3]."),
    sample: int | None = typer.Option(
        None, "--sample", help="N points of a Latin hypercube over the --range keys."),
    ranges: list[str] = typer.Option([], "--range", help="KEY=LO:HI for --sample (repeatable)."),
    sample_seed: int = typer.Option(0, "--sample-seed", help="Seed of the Latin hypercube."),
    seeds: int = typer.Option(1, "--seeds", help=SEEDS_HELP),
    set_: list[str] = typer.Option([], "--set", help=SET_HELP + " Fixed for every run."),
    executor: str = typer.Option("local", "--executor", help=EXECUTOR_HELP),
    out: Path | None = typer.Option(None, "--out", help=OUT_HELP + " Default sweeps/<protocol>."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON row per run on stdout."),
    draw: bool = typer.Option(True, "--figures/--no-figures", help="Heat maps / line plots."),
) -> None:
    """Run a protocol over a grid (--vary) or a Latin-hypercube sample (--sample, --range).

    Each run has an id from its protocol, overrides and seed; its MCAP file and
    row go into OUT/runs/<id>/, and a run already there is not run again (kill
    the sweep, start it again: nothing is lost, nothing is run twice). Writes
    OUT/results.csv and OUT/results.parquet (one row per run) and heat maps
    (two varied keys) or line plots (one) in OUT/figures/. Exit code: 0 when
    every run has its row (failed runs included), 2 bad input (before any run),
    128+N on signal N.
    """
    from ffexp.cli.tables import json_line
    from ffexp.sweeps.executors import parse_executor
    from ffexp.sweeps.grid import execute, prepare

    out = out if out is not None else Path("sweeps") / protocol.stem
    _check_out(out)
    spec = parse_executor(executor)
    prep = prepare(protocol, vary=vary, ranges=ranges, sample=sample, sample_seed=sample_seed,
                   seeds=seeds, fixed=set_)
    with _session(out, spec, f"sweep {prep.target.label}") as (runner, _display):
        result = execute(prep, runner, figures=draw)
    rows = result["rows"]
    if as_json:
        for row in rows:
            typer.echo(json_line(row))
    else:
        keys = [k.text for k in prep.keys]
        _print_summary(f"{prep.target.label}: {len(rows)} runs", rows, keys)
    failed = sum(1 for r in rows if r.get("error"))
    err = as_json
    typer.echo(f"{len(rows)} runs ({failed} failed) in {out}", err=err)
    for p in result["tables"] + result["figures"]:
        typer.echo(f"wrote {p}", err=err)


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
