"""``ffexp run`` and ``ffexp campaign``: the paper's experiments.

Imports only typer, the standard library and light ffexp modules at module
level; the simulator, the analysis and matplotlib load inside the commands.
"""

from __future__ import annotations

from collections.abc import Sequence
from contextlib import nullcontext
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from ffexp.cli._common import (
    EXIT_ABORTED,
    EXIT_OK,
    EXIT_TIMED_OUT,
    SCENE_SET_HELP,
    SET_HELP,
    StopFlag,
    check_cpus,
    cli_errors,
    stop_signals,
    with_scene_sets,
)
from ffexp.cli.live import live_view, serve_after_run
from ffexp.cli.progress import Steps
from ffexp.rig_choice import DEFAULT_DRIVER, DRIVERS, FT_SOURCES, TRACKERS, RigChoice

if TYPE_CHECKING:
    from ffexp.campaign import CampaignEntry
    from ffexp.contracts import RunOutcome
    from ffexp.experiment import RunResult
    from ffexp.live import LiveOptions, LiveServer
    from ffexp.recording import Recording

RIG_HELP = "Rig file (rigs/*.toml): the robot and F/T back-ends and every hardware number."
RIG_SET_HELP = "Override a rig field, e.g. --rig-set robot.port=49939 (repeatable)."
LEAN_HELP = ("Record lean: only the topics the metrics read (no F/T samples, commands, "
             "wire topics, /tf or 3-D scene; the metrics are the same). The file says so "
             "in its 'recording' metadata; report, figures, replay and diff need a full one.")
DRIVER_HELP = (f"Without --rig: the built-in rig of {', '.join(DRIVERS)} (default: sim; "
               "not with --rig).")
WIDE_HELP = "Show every table column (default: as many as fit the terminal)."
TRACKER_HELP = ("Rig tracker.type: the target tracker that judges alignment "
                f"({', '.join(TRACKERS)}).")
CAMERA_HELP = ("Rig tracker.source with tracker.type camera: a device index, a video file "
               "or a stream URL (http://HOST:PORT/...).")
RT_HELP = ("Real-time: SCHED_FIFO where the OS allows it (said when not), the garbage "
           "collector frozen and disabled during the run.")
CPU_HELP = "With --rt: pin the process to this CPU (repeatable)."
LIVE_HELP = ("Serve the run live to Foxglove (WebSocket, foxglove-sdk, subprotocol "
             "foxglove.sdk.v1) on 127.0.0.1:8765 while it runs and after it, until the viewer "
             "disconnects or Ctrl-C; open layouts/ffexp-layout.json there.")
LIVE_ADDRESS_HELP = "With --live (implies it): listen on HOST:PORT (port 0: any free port)."


def outcome_exit_code(outcome: RunOutcome) -> int:
    """0 aligned, 4 timed out without aligning, 3 aborted (README "Exit codes")."""
    from ffexp.contracts import Phase

    if outcome.phase == Phase.ABORT:
        return EXIT_ABORTED
    return EXIT_OK if outcome.aligned else EXIT_TIMED_OUT


def _one(
    steps: Steps, protocol: Path, set_: Sequence[str], rig: RigChoice, out: Path,
    flag: StopFlag, label: str, rt: bool = False, cpus: Sequence[int] = (),
    live: LiveServer | None = None, timeout_s: float | None = None, lean: bool = False,
) -> RunResult:
    with steps.step(f"{label}: loading the protocol and the rig"):
        from ffexp.experiment import run_file
        from ffexp.protocol import load_run_protocol
        from ffexp.rt import realtime

        if timeout_s is None:
            timeout_s = load_run_protocol(protocol, list(set_)).run.timeout_s
    with (realtime(tuple(cpus)) if rt else nullcontext()) as got:
        if got is not None:
            steps.note(f"--rt: {got}")
        with steps.run(label, timeout_s) as show:
            result = run_file(
                protocol, list(set_), rig=rig, out_dir=out, progress=show,
                stop_requested=flag, notice=steps.note, live=live, lean=lean,
            )
    o = result.outcome
    from ffexp.contracts import StopReason

    # the stop's own reason; a run that went on after its seat says it was seated too
    ended_aligned = o.stop_reason is StopReason.ALIGNED
    status = "aligned" if ended_aligned else (o.reason or o.stop_reason.value)
    if o.aligned and not ended_aligned:
        status += "; seated on the way"
    typer.echo(f"{result.path.stem}: {o.phase.name} ({status}) after {o.duration_s:.2f} s")
    typer.echo(f"recording: {result.path}")
    return result


def rig_choice(
    rig: Path | None, driver: str | None, rig_set: list[str], robot_ip: str = "",
    fri_port: int | None = None, ft: str = "", netft: str = "", tracker: str = "",
    camera: str = "",
) -> RigChoice:
    """The rig of a command line: the device flags become overrides of rig fields;
    ``--rig`` with ``--driver`` is a :class:`~ffexp.errors.ConfigError` (one names the
    devices)."""
    if rig is not None and driver is not None:
        from ffexp.errors import ConfigError

        raise ConfigError("--driver", driver, f"--rig {rig} already names the devices; give "
                          "--rig or --driver, not both")
    overrides = list(rig_set)
    if tracker:
        overrides.append(f"tracker.type={tracker!r}")
    if camera:
        if not tracker:
            overrides.append("tracker.type='camera'")
        overrides.append(f"tracker.source={camera!r}")
    if robot_ip:
        overrides.append(f"robot.robot_ip={robot_ip!r}")
    if fri_port is not None:
        overrides.append(f"robot.port={fri_port}")
    if ft:  # another sensor: the table's other keys were the previous sensor's settings
        overrides.append(f"ft={{type = {ft!r}}}")
    if netft:
        host, _, port = netft.rpartition(":") if ":" in netft else (netft, "", "")
        overrides.append(f"ft.host={host!r}")
        if port:
            overrides.append(f"ft.port={port}")
    return RigChoice(path=rig, overrides=tuple(overrides),
                     driver=None if rig else (driver or DEFAULT_DRIVER))


def _check_out(out: Path) -> None:
    from ffexp.errors import ConfigError

    if out.exists() and not out.is_dir():
        raise ConfigError("--out", str(out), "exists and is not a directory")


@cli_errors
def run(
    protocol: Path = typer.Argument(..., help="Run protocol TOML (protocols/method*.toml)."),
    rig: Path | None = typer.Option(None, "--rig", help=RIG_HELP),
    driver: str | None = typer.Option(None, "--driver", help=DRIVER_HELP, show_default=False),
    set_: list[str] = typer.Option([], "--set", help=SET_HELP),
    scene_set: list[str] = typer.Option([], "--scene-set", help=SCENE_SET_HELP),
    rig_set: list[str] = typer.Option([], "--rig-set", help=RIG_SET_HELP),
    out: Path = typer.Option(Path("runs"), "--out", help="Directory for the MCAP recording."),
    fri_port: int | None = typer.Option(
        None, "--fri-port", help="Rig robot.port: local UDP port for FRI (0 = any)."
    ),
    robot_ip: str = typer.Option("", "--robot-ip", help="Rig robot.robot_ip: the KRC's address."),
    ft: str = typer.Option("", "--ft", help=f"Rig ft.type: {', '.join(FT_SOURCES)}."),
    netft: str = typer.Option("", "--netft", help="Rig ft.host and ft.port as HOST[:PORT]."),
    tracker: str = typer.Option("", "--tracker", help=TRACKER_HELP),
    camera: str = typer.Option("", "--camera", help=CAMERA_HELP),
    rt: bool = typer.Option(False, "--rt", help=RT_HELP),
    cpu: list[int] = typer.Option([], "--cpu", help=CPU_HELP),
    live: bool = typer.Option(False, "--live", help=LIVE_HELP),
    live_address: str = typer.Option("", "--live-address", metavar="HOST:PORT",
                                     help=LIVE_ADDRESS_HELP),
    wide: bool = typer.Option(False, "--wide", help=WIDE_HELP),
    lean: bool = typer.Option(False, "--lean", help=LEAN_HELP),
) -> None:
    """Run one experiment; print a summary and the path of its recording.

    Exit code: 0 aligned, 4 timed out without aligning, 3 aborted, 2 bad input,
    1 a device or simulation failure, 128+N on signal N.
    """
    set_ = with_scene_sets(set_, scene_set)
    _check_out(out)
    check_cpus("--cpu", cpu)
    choice = rig_choice(rig, driver, rig_set, robot_ip, fri_port, ft, netft, tracker, camera)
    live_options = _live_options(live, live_address)
    with stop_signals(StopFlag()) as flag, live_view(live_options) as server:
        with Steps() as steps:
            result = _one(steps, protocol, set_, choice, out, flag, protocol.stem, rt, cpu,
                          server, lean=lean)
            recs = []
            if _measured(result):  # a robot that never answered: the file has only events
                with steps.step("loading the recording"):
                    recs = [_load(result.path)]
        code = flag.exit_code()  # a signal during the run; Ctrl-C after it only ends --live
        if recs:
            _print_runs(recs, wide)
        if server is not None:
            serve_after_run(server, flag)
    raise typer.Exit(code if code is not None else outcome_exit_code(result.outcome))


def _live_options(live: bool, address: str) -> LiveOptions | None:
    """``--live`` / ``--live-address`` as the live server's options (None: not live)."""
    if not live and not address:
        return None
    from ffexp.live.address import DEFAULT_ADDRESS, parse_address

    if address:
        return parse_address(address, "--live-address")
    return parse_address(DEFAULT_ADDRESS, "--live")


def _measured(result: RunResult) -> bool:
    """The run got at least one measurement (else its recording has no cycles to show)."""
    from ffexp.contracts import StopReason

    return result.outcome.stop_reason is not StopReason.NO_MEASUREMENT


def _load(path: Path) -> Recording:
    from ffexp.recording import load

    return load(path)


def _print_runs(recs: Sequence[Recording], wide: bool) -> None:
    from ffexp.analysis import COMPARE_COLUMNS, compare_row
    from ffexp.cli.tables import Column, compact_runs, console, fitted_table

    con = console(wide=wide)
    cols = [Column(t, k, p) for t, k, p in COMPARE_COLUMNS]
    rows, day = compact_runs([compare_row(r) for r in recs])
    con.print(fitted_table(con, day or "runs", cols, rows))


@cli_errors
def campaign(
    campaign_file: Path = typer.Argument(..., help="Campaign TOML (protocols/paper.toml)."),
    rig: Path | None = typer.Option(None, "--rig", help=RIG_HELP),
    driver: str | None = typer.Option(None, "--driver", help=DRIVER_HELP, show_default=False),
    set_: list[str] = typer.Option([], "--set", help="Override in every run's protocol, e.g. "
                                   "--set run.timeout_s=2 (repeatable)."),
    scene_set: list[str] = typer.Option([], "--scene-set", help=SCENE_SET_HELP
                                        + " In every run."),
    rig_set: list[str] = typer.Option([], "--rig-set", help=RIG_SET_HELP),
    out: Path = typer.Option(
        Path("runs"), "--out",
        help="Parent directory: the campaign writes into OUT/<campaign>-<time>/.",
    ),
    wide: bool = typer.Option(False, "--wide", help=WIDE_HELP),
    draw: bool = typer.Option(
        True, "--figures/--no-figures", help="Draw the figures (PNG and SVG) at the end."
    ),
    resume: Path | None = typer.Option(
        None, "--resume", help="Continue the campaign in this directory (stopped by Ctrl-C): "
        "its finished runs are kept, only the missing ones run."),
) -> None:
    """Run several protocols and compare them with the paper's Table (res_par).

    Everything goes into one campaign directory OUT/<campaign>-<time>/: the
    recordings, the figures (PNG and SVG) and campaign.json, which
    `ffexp report` reads. After Ctrl-C, --resume DIR runs only what is missing.
    Exit code: 0 when every run ran to its end (aligned or not), 2 bad input, 128+N on
    signal N.
    """
    set_ = with_scene_sets(set_, scene_set)
    with Steps() as early, early.step("starting"):  # the imports take a second or two
        from ffexp.campaign import check_campaign, run_campaign
    _check_out(out)
    with stop_signals(StopFlag()) as flag, Steps() as steps:
        choice = rig_choice(rig, driver, rig_set)
        with steps.step(f"checking {campaign_file.name}, its protocols and the rig"):
            checked = check_campaign(campaign_file, set_, choice)
        camp, entries = checked
        with steps.step(f"campaign {camp.name}", total=len(entries)) as advance:

            def one(entry: CampaignEntry, camp_dir: Path) -> RunResult:
                result = _one(steps, entry.protocol, entry.overrides, choice, camp_dir, flag,
                              entry.label, timeout_s=entry.timeout_s)
                advance()
                return result

            done = run_campaign(campaign_file, set_, rig=choice, out_parent=out, run_one=one,
                                stop_requested=flag, checked=checked, resume=resume)
        with steps.step("loading the recordings", total=len(done.results)) as advance:
            recs = [_load(p) for p in done.kept]
            for r in done.results:
                if _measured(r):
                    recs.append(_load(r.path))
                advance()
        _paper_table(recs, wide)
        _print_runs(recs, wide)
        figures = (_campaign_figures(steps, camp.name, recs, done.directory / "figures")
                   if draw else [])
    if figures:
        typer.echo(f"figures: {len(figures)} files (PNG and SVG) in {figures[0].parent}")
    typer.echo(f"campaign: {done.directory} (ffexp report {done.directory})")
    code = flag.exit_code()
    raise typer.Exit(code if code is not None else EXIT_OK)


def _paper_table(recs: Sequence[Recording], wide: bool) -> None:
    from ffexp.analysis import PAPER_COLUMNS, paper_row
    from ffexp.cli.tables import Column, compact_runs, console, fitted_table

    con = console(wide=wide)
    cols = [Column(t, k, p, digits=3) for t, k, p in PAPER_COLUMNS]
    rows, _day = compact_runs([row for row in (paper_row(r) for r in recs) if row is not None])
    title = ("the paper (Table res_par, its clock) vs ours (since the tare): outcome, "
             "agreement, times, breaks")
    con.print(fitted_table(con, title, cols, rows))


def _campaign_figures(
    steps: Steps, name: str, recs: Sequence[Recording], out_dir: Path
) -> list[Path]:
    from ffexp import figures
    from ffexp.analysis import run_name
    from ffexp.errors import FfexpError

    if not recs:
        return []
    paths: list[Path] = []
    with steps.step("drawing figures", total=1 + 2 * len(recs)) as advance:
        try:
            with figures.style():
                labelled = [(_run_title(rec), rec) for rec in recs]
                fig = figures.campaign_figure(labelled, name)
                paths.extend(figures.save(fig, out_dir, f"{name}_all_wrench"))
                advance()
            for rec in recs:
                for path in figures.write_run_figures(rec, out_dir, run_name(rec)):
                    paths.append(path)
                advance(2)
        except FfexpError as exc:
            steps.note(f"warning: figures incomplete: {exc}")
    return paths


def _run_title(rec: Recording) -> str:
    """A run's title in figures: its name and its overrides."""
    import json

    from ffexp.analysis import run_name

    meta = rec.metadata.get("run", {})
    try:
        overrides = json.loads(meta.get("overrides", "[]"))
    except json.JSONDecodeError:
        overrides = []
    return run_name(rec) + (f" ({' '.join(overrides)})" if overrides else "")
