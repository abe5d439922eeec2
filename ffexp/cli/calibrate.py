"""``ffexp calibrate`` and ``ffexp resimulate``: the simulator fitted to a rig's recordings.

Imports only typer, the standard library and light ffexp modules at module
level; the simulator, numpy and scipy load inside the commands.
"""

from __future__ import annotations

import copy
import os
import sys
from pathlib import Path
from typing import Any

import typer

from ffexp.cli._common import EXIT_FAILURE, check_scene_file, cli_errors, fail
from ffexp.cli.progress import Steps

#: Columns of the terminal's tables that give way first when it is narrow (the report, the
#: CSV and the JSON have them all).
_PRIORITY = {"note": 6, "method": 5, "bounds": 4, "stage": 3, "start": 2, "yaw": 6,
             "target": 5, "torque": 4, "joints": 3, "tcp": 2, "set": 2, "agree": 1}
SCENE_HELP = "The scene the simulator starts from (default: data/scenes/paper.toml)."
DEFAULT_SCENE = Path(__file__).resolve().parents[2] / "data" / "scenes" / "paper.toml"


@cli_errors
def resimulate(
    recording: Path = typer.Argument(..., help="A run recording (.mcap) with the commands "
                                     "its robot applied (an LWR4+'s, over FRI or simulated)."),
    out: Path = typer.Option(..., "--out", help="The simulated recording (.mcap) to write."),
    scene: Path | None = typer.Option(None, "--scene", help="Replay in this scene (default: "
                                      "the recording's own, a simulator's run)."),
    scene_set: list[str] = typer.Option([], "--scene-set", help="Override a scene key, e.g. "
                                        "--scene-set target.mu=0.006 (repeatable)."),
) -> None:
    """Replay a recording's applied commands, open loop, into the simulated rig from the
    recorded start; write what the simulator measured on the same topics and times.

    `ffexp diff RUN.mcap SIM.mcap --atol 0.1` then shows where they part. Never overwrites
    --out. Exit 0, or 2 on bad input (nothing written).
    """
    from ffexp.calibrate.simfile import resimulate as run
    from ffexp.errors import ConfigError
    from ffexp.recording.kind import check_run_recording

    if out.exists() and out.resolve() != recording.resolve():  # itself: said more precisely
        raise ConfigError("--out", str(out), "exists; a recording is never overwritten")
    check_scene_file("--scene", scene)
    check_run_recording(recording)
    with Steps() as steps, steps.step(f"replaying {recording.name} into the simulator"):
        r = run(recording, out, scene, scene_set)
    c = r.comparison
    typer.echo("rms recorded - simulated: " + ", ".join(
        f"{k} {v:.3g}" for k, v in c.rms.items() if v == v))
    typer.echo(f"outcome: recorded {r.outcome_recorded}; simulated {r.outcome_simulated}")
    if r.failed:
        typer.echo(f"warning: {r.failed}")
    typer.echo(f"recording: {r.path}")


@cli_errors
def calibrate(
    recordings: list[Path] = typer.Argument(..., help="Recordings (.mcap) to fit to."),
    fit: list[str] = typer.Option(..., "--fit", help="A scene key to fit, KEY or KEY=LO:HI "
                                  "(repeatable), e.g. --fit target.mu=0.002:0.01."),
    out: Path = typer.Option(..., "--out", help="The calibrated scene (.toml) to write; "
                             "never overwritten, never written when the fit did not "
                             "converge."),
    scene: Path = typer.Option(DEFAULT_SCENE, "--scene", help=SCENE_HELP, show_default=False),
    scene_set: list[str] = typer.Option([], "--scene-set", help="Override a key of the start "
                                        "scene (repeatable)."),
    holdout: list[Path] = typer.Option([], "--holdout", help="A recording to predict, not "
                                       "fit (repeatable): held-out validation."),
    report: Path | None = typer.Option(None, "--report", help="Directory for the report "
                                       "(calibration.html, .json, figures); default: "
                                       "beside --out."),
    jobs: int = typer.Option(min(2, os.cpu_count() or 1), "--jobs", "-j",
                             help="Rollouts in parallel (processes)."),
    batch: int = typer.Option(1, "--batch", help="Rollouts each process steps together, "
                              "their physics one dispatch a cycle (the same fit; 1: one "
                              "at a time)."),
    keep_unidentified: bool = typer.Option(False, "--keep-unidentified", help="Keep a "
                                           "parameter no recording excites at its start "
                                           "value (reported as not identified) instead of "
                                           "stopping."),
    wide: bool = typer.Option(False, "--wide", help="Show every table column (default: as "
                              "many as fit the terminal)."),
    force: bool = typer.Option(False, "--force", help="Write the scene even when the fit is "
                               "not consistent with the data (the data put a value outside "
                               "its interval)."),
) -> None:
    """Fit scene keys to recordings by replaying them into the simulator, in stages:
    the loop's delay (every whole cycle), the smooth parameters (least squares), the
    F/T path's delay (whole samples), contact (CMA-ES). Reports each value with its
    interval and whether the data identify it, residuals per signal, held-out
    validation, figures and an HTML page; writes the scene with its provenance.

    Exit 0, 1 when the fit did not converge or is not consistent with the data (no scene
    written; --force writes one that is not consistent), 2 on bad input.
    """
    from ffexp.calibrate.report import parameter_rows, residual_rows, write_report
    from ffexp.calibrate.run import calibrate as run
    from ffexp.calibrate.scene_out import scene_text, set_key, write_scene
    from ffexp.cli.tables import Column, console, fitted_table
    from ffexp.errors import ConfigError
    from ffexp.recording.kind import check_run_recording
    from ffexp.revision import source_revision

    if out.exists():
        raise ConfigError("--out", str(out), "exists; the calibrated scene is never "
                          "overwritten")
    if out.suffix != ".toml":
        raise ConfigError("--out", str(out), "a scene file ends in .toml")
    if not out.parent.is_dir():
        raise ConfigError("--out", str(out), f"no directory {out.parent}")
    if jobs < 1:
        raise ConfigError("--jobs", str(jobs), "at least 1")
    if batch < 1:
        raise ConfigError("--batch", str(batch), "at least 1")
    check_scene_file("--scene", scene)
    for path in (*recordings, *holdout):
        check_run_recording(path)
    report_dir = report if report is not None else out.parent / f"{out.stem}-report"
    if report_dir.exists() and not report_dir.is_dir():
        raise ConfigError("--report", str(report_dir), "exists and is not a directory")
    with _Bars() as bars:
        res, params = run(recordings, fit, scene, holdout=holdout, scene_overrides=scene_set,
                          jobs=jobs, progress=bars.update, keep_unidentified=keep_unidentified,
                          batch=batch)
    con = console(wide=wide)  # the terminal's width (80 when piped); the report has all
    rows = parameter_rows(res)
    cols = [Column(k, k, _PRIORITY.get(k, 0), left=k in ("key", "note"))
            for k in rows[0]]
    con.print(fitted_table(con, "calibrated parameters", cols, rows))
    rrows = residual_rows(res, res.inputs)
    con.print(fitted_table(con, "residuals (rms, start -> result) and validation",
                           [Column(k, k, _PRIORITY.get(k, 0), left=k == "recording")
                            for k in rrows[0]], rrows))
    header = [
        "Calibrated by `ffexp calibrate` (docs/calibrate.md)",
        f"source revision: {source_revision()}",
        f"start scene: {scene}" + (f" with {', '.join(scene_set)}" if scene_set else ""),
        "fitted to: " + ", ".join(str(p) for p in recordings),
        *(["held out: " + ", ".join(str(p) for p in holdout)] if holdout else []),
        f"{res.rollouts} rollouts in {res.elapsed_s:.1f} s; converged: "
        f"{'yes' if res.converged else 'no'}; consistent with the data: "
        f"{'yes' if res.consistent else 'NO (' + '; '.join(res.inconsistent) + ')'}",
        *(f"warning: {w}" for w in res.warnings),
        *(f"{e.key} = {e.value:.6g}, 95 % [{e.ci_lo:.6g}, {e.ci_hi:.6g}], "
          f"{'identified' if e.identified else 'NOT identified'} ({e.stage}: {e.method})"
          for e in res.estimates),
        *(f"residual rms {r['recording']} ({r['set']}): force {r['force']} N, tcp {r['tcp']} m"
          for r in rrows),
    ]
    for w in res.warnings:
        typer.echo(f"warning: {w}", err=True)
    writes = res.converged and (res.consistent or force)
    written = write_report(report_dir, res, res.inputs, header, out if writes else None)
    for path in written:
        if path.suffix == ".html":
            typer.echo(f"report: {path}")
    if not res.converged:
        bad = [s.name for s in res.stages if s.kept and not s.converged]
        raise fail(f"the fit did not converge ({', '.join(bad)}); no scene written "
                   f"(report: {report_dir})", EXIT_FAILURE)
    if not res.consistent and not force:
        raise fail(f"the fit is not consistent with the data ({'; '.join(res.inconsistent)}); "
                   f"no scene written (--force writes it; report: {report_dir})", EXIT_FAILURE)
    data = copy.deepcopy(res.base_scene)
    notes = {}
    by = {p.key: p for p in params}
    for e in res.estimates:
        set_key(data, e.key, by[e.key].value(e.value))
        notes[e.key] = (f"calibrated, 95 % [{e.ci_lo:.6g}, {e.ci_hi:.6g}]"
                        + ("" if e.identified else ", NOT identified") + f"; was {e.start:g}")
    write_scene(out, scene_text(data, header, notes))
    typer.echo(f"scene: {out}")


class _Bars:
    """A rich bar per stage of the fit (plain lines on stderr without a terminal)."""

    def __init__(self) -> None:
        self.enabled = sys.stderr.isatty()
        self.tasks: dict[str, Any] = {}
        self.progress: Any = None

    def __enter__(self) -> _Bars:
        if self.enabled:
            from rich.console import Console
            from rich.progress import (
                BarColumn,
                MofNCompleteColumn,
                Progress,
                SpinnerColumn,
                TextColumn,
                TimeElapsedColumn,
            )

            self.progress = Progress(
                SpinnerColumn(), TextColumn("{task.description:<10}"), BarColumn(bar_width=24),
                MofNCompleteColumn(), TextColumn("{task.fields[status]}"), TimeElapsedColumn(),
                console=Console(stderr=True))
            self.progress.start()
        return self

    def __exit__(self, *exc: object) -> None:
        if self.progress is not None:
            self.progress.stop()

    def update(self, stage: str, done: int, total: int | None, status: str) -> None:
        """``(stage, done, total, status)`` of :mod:`ffexp.calibrate.fit`."""
        bar = self.progress
        if bar is None:
            if stage not in self.tasks and stage != "rollouts":
                self.tasks[stage] = None
                print(f"calibrate: {stage}: {status}", file=sys.stderr, flush=True)
            return
        if stage == "rollouts":  # every replay, all along: a counter of its own
            if stage not in self.tasks:
                self.tasks[stage] = (bar.add_task(stage, total=None, status=status), None)
            bar.update(self.tasks[stage][0], completed=done, status=status)
            return
        if stage not in self.tasks:
            for name, (task, last) in self.tasks.items():  # the previous stages are done
                if name == "rollouts":
                    continue
                bar.update(task, completed=last or 0, total=last)
                bar.stop_task(task)
            self.tasks[stage] = (bar.add_task(stage, total=total, status=status), total)
        task = self.tasks[stage][0]
        self.tasks[stage] = (task, total)
        bar.update(task, completed=done, total=total, status=status)
