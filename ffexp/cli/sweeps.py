"""``ffexp sweep``, ``ffexp limits`` and ``ffexp reproduce``: many runs of one protocol.

Heavy imports (the simulator, pandas, matplotlib, ray) happen inside the
commands, never at module import (``ffexp --help`` must stay fast). The
engine is :mod:`ffexp.sweeps` (docs/sweeps.md).
"""

from __future__ import annotations

import sys
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from ffexp.cli._common import (
    SCENE_SET_HELP,
    SET_HELP,
    StopFlag,
    cli_errors,
    count,
    stop_signals,
    with_scene_sets,
)
from ffexp.cli.run import RIG_HELP
from ffexp.sweeps.rigs import simulated_drivers, simulated_robots

if TYPE_CHECKING:
    from ffexp.sweeps.engine import Runner
    from ffexp.sweeps.executors import ExecutorSpec
    from ffexp.sweeps.rigs import StudyRig
    from ffexp.sweeps.session import Display

EXECUTOR_HELP = (
    "local[:WORKERS] (a process pool; default all CPUs); batch:N or local:WORKERS,batch:N "
    "(each worker steps batches of up to N runs together, the same rows); or Ray: ray "
    "(join the running "
    "cluster, else start one here, as ray.init()), ray:auto (only join; an error when none "
    "runs), ray:HOST:PORT (join that cluster), ray://HOST:PORT (client), ray:local (always "
    "start one here); ray[:ADDRESS],batch:N (batches of up to N runs as Ray tasks, one CPU "
    "each)."
)
OUT_HELP = (
    "Sweep directory (runs, results.csv/.parquet, figures). Runs already in it are not run "
    "again. With Ray it must be a path every worker sees (shared storage)."
)
SEEDS_HELP = "Noise seeds per point: the protocol's seed and the next N-1."
RECORDING_HELP = (
    "How the runs record: --lean only the topics the metrics read (a third of the cost "
    "per cycle; report, figures, replay and diff need a full file), --full every topic. "
    "The rows are the same either way; a run done before counts when its recording "
    "serves (a full one always, a lean one for --lean); a lean one is run again for "
    "--full. The row's 'recording' column and the study's JSON say which.")
STUDY_RIG_HELP = RIG_HELP + (
    " The runs go to parallel workers: only a rig simulated in the worker's process (robot "
    f"{', '.join(simulated_robots())} with the simulator's F/T and tracker) runs a study; a "
    "lab or emulator rig is refused. The rig is part of each run's id; the row's 'rig' "
    "column and the study's JSON name it.")
STUDY_RIG_SET_HELP = ("Override a rig field, KEY=VALUE as for ffexp run (repeatable; with or "
                      "without --rig), e.g. robot.force_mode_damping=0.01 with "
                      "--driver ur-sim.")
STUDY_DRIVER_HELP = (f"Without --rig: the built-in rig of {', '.join(simulated_drivers())} "
                     "(default: sim; not with --rig); a study runs on a simulated robot only.")


def _check_out(out: Path) -> None:
    from ffexp.errors import ConfigError

    if out.exists() and not out.is_dir():
        raise ConfigError("--out", str(out), "exists and is not a directory")


@contextmanager
def _session(out: Path, spec: ExecutorSpec, label: str,
             lean: bool = False) -> Iterator[tuple[Runner, Display]]:
    from ffexp.sweeps.engine import Stopped
    from ffexp.sweeps.session import session

    with stop_signals(StopFlag()) as flag:
        try:
            with session(out, spec, label, flag, lean=lean) as (runner, display):
                yield runner, display
        except Stopped:
            pass
        except KeyboardInterrupt:  # the second signal: the workers were ended
            if not flag():
                raise
        code = flag.exit_code()
        if code is not None:
            typer.echo(f"{label}: stopped; finished runs are kept in {out} (run the same "
                       "command again to go on)", err=True)
            raise typer.Exit(code)


def _study_rig(rig: Path | None, driver: str | None, rig_set: list[str]) -> StudyRig | None:
    """The study's rig, as ``ffexp run`` reads the options, refused unless simulated in the
    workers' process (one line naming the rig and the field, exit 2; before any run)."""
    from ffexp.cli.run import rig_choice
    from ffexp.sweeps.rigs import study_rig

    return study_rig(rig_choice(rig, driver, rig_set))


def _finite_values(vary: Sequence[str]) -> None:
    """Every number of every ``--vary KEY=V1,V2,...`` finite (a ConfigError naming it)."""
    import math

    from ffexp.errors import ConfigError
    from ffexp.sweeps.keys import parse_assignment

    for text in vary:
        _key, values = parse_assignment(text, "--vary")
        stack: list[object] = list(values)
        while stack:
            v = stack.pop()
            if isinstance(v, list):
                stack.extend(v)
            elif isinstance(v, float) and not math.isfinite(v):
                raise ConfigError("--vary", text, f"{v} is not a finite number")


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
    scene_set: list[str] = typer.Option([], "--scene-set", help=SCENE_SET_HELP),
    rig: Path | None = typer.Option(None, "--rig", help=STUDY_RIG_HELP),
    driver: str | None = typer.Option(None, "--driver", help=STUDY_DRIVER_HELP,
                                      show_default=False),
    rig_set: list[str] = typer.Option([], "--rig-set", help=STUDY_RIG_SET_HELP),
    executor: str = typer.Option("local", "--executor", help=EXECUTOR_HELP),
    out: Path | None = typer.Option(
        None, "--out", help=OUT_HELP + " Default runs/sweeps/<protocol>."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON row per run on stdout."),
    draw: bool = typer.Option(True, "--figures/--no-figures", help="Heat maps / line plots."),
    lean: bool = typer.Option(False, "--lean/--full", help=RECORDING_HELP + " Default: full "
                              "(a sweep's runs are opened one by one)."),
) -> None:
    """Run a protocol over a grid (--vary) or a Latin-hypercube sample (--sample, --range).

    Each run has an id from its protocol, overrides and seed (and the rig, with
    --rig, --driver or --rig-set: a simulated arm's rig, the UR5e's or the FR3's);
    its MCAP file and row go into OUT/runs/<id>/, and a run already there is not
    run again (kill the sweep, start it again: nothing is lost, nothing is run
    twice). Writes
    OUT/results.csv and OUT/results.parquet (one row per run) and heat maps
    (two varied keys) or line plots (one) in OUT/figures/. --lean records only
    what the metrics read (the same rows, cheaper runs). Exit code: 0 when
    every run has its row (failed runs included), 2 bad input (before any run),
    128+N on signal N.
    """
    set_ = with_scene_sets(set_, scene_set)
    from ffexp.cli.tables import json_line
    from ffexp.sweeps.executors import parse_executor
    from ffexp.sweeps.grid import execute, prepare
    from ffexp.sweeps.session import spinner
    from ffexp.sweeps.table import recordings_note

    count("--seeds", seeds)
    count("--sample", sample)
    _finite_values(vary)
    out = out if out is not None else Path("runs") / "sweeps" / protocol.stem
    _check_out(out)
    spec = parse_executor(executor)
    with spinner(sys.stderr.isatty(), "checking the rig and every point against the "
                 "protocol and scene"):
        study_rig = _study_rig(rig, driver, rig_set)
        prep = prepare(protocol, vary=vary, ranges=ranges, sample=sample,
                       sample_seed=sample_seed, seeds=seeds, fixed=set_, rig=study_rig)
    with _session(out, spec, f"sweep {prep.target.label}", lean) as (runner, _display):
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
    typer.echo(f"{len(rows)} runs ({failed} failed) in {out}, {recordings_note(rows)}",
               err=err)
    for p in result["tables"] + result["figures"]:
        typer.echo(f"wrote {p}", err=err)


@cli_errors
def limits(
    protocol: Path = typer.Argument(..., help="Run protocol (TOML)."),
    key: list[str] = typer.Option(..., "--key", help="The key (twice: a plane), e.g. "
                                  "align.k_ri[3] for k_xp, align.f_ref[2] for f_ref."),
    range_: list[str] = typer.Option(..., "--range", help="LO:HI of each --key, in order."),
    seeds: int = typer.Option(1, "--seeds", help=SEEDS_HELP + " A point aligns when more "
                              "than half of them do."),
    resolution: list[float] = typer.Option(
        [], "--resolution", help="Bracket width to stop at, in the key's unit (one, or one "
        "per key). Default: 1/16 of each range."),
    coarse: int = typer.Option(5, "--coarse", help="Points of the coarse grid (per ray)."),
    n_rays: int = typer.Option(8, "--rays", help="Two keys: rays from the box centre."),
    max_breaks: int | None = typer.Option(
        None, "--max-breaks", help="A run aligns only with at most this many contact breaks "
        "(the paper's upper limit: contact breaks above it). Default: any."),
    set_: list[str] = typer.Option([], "--set", help=SET_HELP + " Fixed for every run."),
    scene_set: list[str] = typer.Option([], "--scene-set", help=SCENE_SET_HELP),
    rig: Path | None = typer.Option(None, "--rig", help=STUDY_RIG_HELP),
    driver: str | None = typer.Option(None, "--driver", help=STUDY_DRIVER_HELP,
                                      show_default=False),
    rig_set: list[str] = typer.Option([], "--rig-set", help=STUDY_RIG_SET_HELP),
    executor: str = typer.Option("local", "--executor", help=EXECUTOR_HELP),
    out: Path | None = typer.Option(
        None, "--out", help=OUT_HELP + " Default runs/sweeps/<protocol>-limits."),
    as_json: bool = typer.Option(False, "--json", help="Print the limits as JSON lines."),
    lean: bool = typer.Option(True, "--lean/--full", help=RECORDING_HELP + " Default: lean "
                              "(the search reads only its runs' rows)."),
) -> None:
    """The limits of a gain (or f_ref) between "aligns" and "does not", by the outcome rule.

    A point aligns when its runs' outcome (ffexp.outcome: the seat kept, the
    contact not breaking after the first contact's transient) is "aligned". A
    coarse grid over LO:HI, then bisection in every bracket where that changes,
    to the resolution, each point run with every seed. Prints each limit with
    its bracket (lower: aligns above it; upper: aligns below it), the outcome
    on its other side (held contact, did not slide; contact kept breaking) and
    plots the outcome against the key (OUT/figures/limits.png). With --key
    twice: the boundary in the plane, by bisection along rays from the centre.
    Runs are cached by id in OUT: the same call twice gives the same answer.
    The runs record lean unless --full; they run on the built-in rig unless
    --rig, --driver or --rig-set name a simulated one. Exit code: 0 done, 2 bad
    input (before any run), 128+N on signal N.
    """
    set_ = with_scene_sets(set_, scene_set)
    import json

    from ffexp.cli.tables import json_line
    from ffexp.errors import ConfigError
    from ffexp.sweeps import plots, table
    from ffexp.sweeps.executors import parse_executor
    from ffexp.sweeps.keys import parse_key, parse_range
    from ffexp.sweeps.plan import Target, seeds_of
    from ffexp.sweeps.reproduce import search_budget
    from ffexp.sweeps.searches import LimitSearch
    from ffexp.sweeps.table import recordings_note
    from ffexp.sweeps.worker import recording_kind

    for option, n in (("--seeds", seeds), ("--coarse", coarse), ("--rays", n_rays)):
        count(option, n)
    out = out if out is not None else Path("runs") / "sweeps" / f"{protocol.stem}-limits"
    _check_out(out)
    spec = parse_executor(executor)
    if len(key) != len(range_):
        raise ConfigError("--range", " ".join(range_), "give one --range LO:HI per --key")
    keys = [parse_key(k, "--key") for k in key]
    if len({k.text for k in keys}) < len(keys):
        raise ConfigError("--key", " ".join(key), "the same key twice: a plane needs two "
                          "different keys")
    spans = []
    for text in range_:
        _k, lo, hi = parse_range(text, "--range")
        spans.append((lo, hi))
    if not protocol.is_file():
        raise ConfigError(str(protocol), "", "file not found")
    target = Target(protocol, tuple(set_), rig=_study_rig(rig, driver, rig_set))
    res = resolution or [(hi - lo) / 16 for lo, hi in spans]
    search = LimitSearch(target, keys, spans, seeds_of(target, seeds), list(res), coarse,
                         n_rays, max_breaks=max_breaks)
    search.check()
    with _session(out, spec, f"limits {target.label}", lean) as (runner, _display):
        runner.plan(search_budget(search))  # the time left counts the bisection's runs
        search.run(runner)
        runner.plan(0)
        found = search.limits_rows()
        table.write(table.frame(search.rows), runner.out_dir)
        (runner.out_dir / "limits.json").write_text(json.dumps({
            "kind": "limits", "protocol": str(protocol), "rig": target.rig_name,
            "keys": key, "ranges": spans,
            "resolution": search.resolution, "seeds": search.seeds, "max_breaks": max_breaks,
            "limits": found, "recording": recording_kind(lean),
        }, indent=2) + "\n")
        names = [k.text for k in keys]
        fig = plots.limits_figure(
            search.points(), names, [tuple(r[n] for n in names) for r in found],
            f"{target.label}: {' x '.join(names)}, {len(search.seeds)} seed(s)",
            runner.out_dir / "figures" / "limits.png", plots.nominal_values(target, keys))
    if as_json:
        for row in found:
            typer.echo(json_line(row))
    else:
        _print_limits(target.label, found, names, search.resolution)
    typer.echo(f"{len(search.rows)} runs looked at ({recordings_note(search.rows)}); table "
               f"and limits.json in {out}; figure {fig}", err=as_json)


def _print_limits(
    label: str, found: Sequence[dict[str, Any]], names: Sequence[str], resolution: Sequence[float]
) -> None:
    from ffexp.cli.tables import console

    res = ", ".join(f"{n} {r:.4g}" for n, r in zip(names, resolution, strict=True))
    if not found:
        typer.echo(f"{label}: the outcome does not change over the range (resolution {res})")
        return
    con = console()
    if len(names) == 1 and len(found) > 2:
        con.print(f"{label}: the outcome changes {len(found)} times over the range "
                  "(not one lower and one upper limit)")
    for row in found:
        where = ", ".join(f"{n} {row[n]:.4g} (bracket {row[n + ' from']:.4g} .. "
                          f"{row[n + ' to']:.4g})" for n in names)
        kind = row["kind"] if len(names) == 1 else f"ray {row['ray']}"
        side = {"lower": "below", "upper": "above"}.get(row["kind"], "beyond")
        beyond = f"; {side} it: {row['beyond']}" if row.get("beyond") else ""
        con.print(f"{kind} limit: {where}; aligned fraction {row['lo_fraction']:.2g} -> "
                  f"{row['hi_fraction']:.2g}{beyond}")
    con.print(f"resolution: {res}")


@cli_errors
def reproduce(
    config: Path = typer.Option(
        Path("protocols/reproduce.toml"), "--config",
        help="The study: paper runs, uncertain scene keys (ranges + sample, or a grid), seeds, "
        "limit searches."),
    set_: list[str] = typer.Option([], "--set", help=SET_HELP + " In every paper run."),
    scene_set: list[str] = typer.Option([], "--scene-set", help=SCENE_SET_HELP),
    rig: Path | None = typer.Option(None, "--rig", help=STUDY_RIG_HELP),
    driver: str | None = typer.Option(None, "--driver", help=STUDY_DRIVER_HELP,
                                      show_default=False),
    rig_set: list[str] = typer.Option([], "--rig-set", help=STUDY_RIG_SET_HELP),
    executor: str = typer.Option("local", "--executor", help=EXECUTOR_HELP),
    out: Path | None = typer.Option(
        None, "--out", help=OUT_HELP + " Default runs/sweeps/<config name>."),
    as_json: bool = typer.Option(False, "--json", help="Print the claim summary as JSON lines."),
    lean: bool | None = typer.Option(None, "--lean/--full", help=RECORDING_HELP + " Default: "
                                     "the config's recording (lean unless it says full).",
                                     show_default=False),
) -> None:
    """The paper check: each claim the simulator can test, over scenes of uncertain rig
    parameters, as the fraction of scenes where it holds beside the paper's statement.

    Writes OUT/scenes.csv (per scene and seed: each run's outcome and each claim),
    OUT/claims.csv (the summary), OUT/limits.csv (limits at the nominal scene),
    OUT/results.csv/.parquet (every run) and OUT/figures/claims.png. Runs are
    cached by id in OUT (run it again: nothing is run twice). The runs record
    lean unless the config says recording = "full" (or --full); every paper run is
    on the built-in rig unless --rig, --driver or --rig-set name a simulated one.
    Exit code: 0 done, 2 bad input (before any run), 128+N on signal N.
    """
    set_ = with_scene_sets(set_, scene_set)
    from ffexp.cli.tables import json_line
    from ffexp.sweeps import reproduce as study_mod
    from ffexp.sweeps.executors import parse_executor
    from ffexp.sweeps.session import spinner
    from ffexp.sweeps.table import recordings_note

    spec = parse_executor(executor)
    with spinner(sys.stderr.isatty(), f"checking {config}: every scene of every paper run"):
        study = study_mod.load(config, set_, rig=_study_rig(rig, driver, rig_set))
    out = out if out is not None else Path("runs") / "sweeps" / study.config.name
    _check_out(out)
    n_runs = len(study.scenes) * len(study.targets) * len(study.config.seeds)
    if lean is None:
        lean = study.config.recording == "lean"
    with _session(out, spec, f"reproduce {study.config.name}", lean) as (runner, display):
        display.note(f"{len(study.scenes)} scenes x {len(study.targets)} paper runs x "
                     f"{len(study.config.seeds)} seed(s) = {n_runs} runs, and "
                     f"{len(study.searches)} limit search(es) at the nominal scene")
        result = study_mod.run(study, runner)
        paths = study_mod.write(study, result, runner.out_dir)
    if as_json:
        for row in result["summary"]:
            typer.echo(json_line(row))
    else:
        _print_claims(study.config.name, result["summary"])
        if result["flips"]:
            typer.echo("flips between neighbouring grid points (flips/pairs): " + ", ".join(
                f"{f['outcome']} {f['flips']}/{f['pairs']}" for f in result["flips"]))
        for r in result.get("regions", []):
            typer.echo(_region_line(r))
    typer.echo(f"wrote {', '.join(p.name for p in paths)} in {out} "
               f"({recordings_note(result['rows'])})", err=as_json)


def _region_line(r: dict[str, Any]) -> str:
    """One claim's region: its fraction of the scenes, and its centre beside the nominal
    scene (each key: centre, nominal, the span of the scenes where it holds)."""
    frac = r["fraction"]
    head = (f"region where {r['claim']!r} holds: {r['holds']} of {r['scenes']} scenes"
            + (f" ({100 * frac:.0f} %)" if frac is not None else ""))
    if not r["centre"]:
        return head + "; no centre"
    parts = [f"{k} {v:.4g} (nominal {r['nominal'].get(k, float('nan')):.4g}, span "
             f"{r['span'].get(k, 0.0):.2f} of the box)" for k, v in r["centre"].items()]
    return head + "; centre: " + ", ".join(parts)


def _print_claims(name: str, summary: Sequence[dict[str, Any]]) -> None:
    from ffexp.cli.tables import Column, console, fitted_table

    rows = []
    for s in summary:
        frac = s["fraction"]
        nominal = s.get("nominal")
        rows.append({
            "claim": s["claim"], "paper": s["paper"],
            "nominal": "-" if nominal is None else ("holds" if nominal else "fails"),
            "agree": "-" if nominal is None else ("yes" if nominal else "NO"),
            "holds": f"{s['holds']}/{s['scenes']}" + (f" ({frac:.0%})" if frac is not None
                                                      else ""),
            "note": s.get("note") or (f"{s['not judged']} not judged" if s["not judged"]
                                      else ""),
        })
    con = console()
    cols = [Column("claim", "claim"), Column("paper says", "paper"),
            Column("nominal scene", "nominal"), Column("agree", "agree"),
            Column("holds in (scenes)", "holds")]
    con.print(fitted_table(con, f"{name}: the paper's claims, at the nominal scene and over "
                                "the scenes", cols, rows))
    for row in rows:
        if row["note"]:
            con.print(f"{row['claim']}: {row['note']}")
