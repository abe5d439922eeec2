"""``ffexp run`` and ``ffexp campaign``: the paper's experiments."""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path

import typer
from rich.console import Console
from rich.table import Table

from ffexp import controllers
from ffexp.analysis import compare_rows, metrics, run_info, write_run_figures
from ffexp.cli._common import SET_HELP, StopFlag, cli_errors, plain_table, stop_signals
from ffexp.cli.records import compare_table
from ffexp.contracts import Phase, Progress
from ffexp.errors import FfexpError
from ffexp.experiment import DRIVERS, FT_SOURCES, RigChoice, RunResult, load_campaign, run_file
from ffexp.recording import load

console = Console(width=170)


def _progress_printer(name: str) -> tuple[Callable[[Progress], None], Callable[[], None]]:
    tty = sys.stderr.isatty()
    last = [-1.0]

    def show(p: Progress) -> None:
        line = (
            f"{name}: {p.phase.name:<8} t={p.time_s:6.2f} s  f_z={p.f_z_n:+6.2f} N  "
            f"contacts={p.contacts} breaks={p.breaks}"
        )
        if tty:
            print("\r" + line, end="", file=sys.stderr, flush=True)
        elif p.time_s - last[0] >= 5.0:
            last[0] = p.time_s
            print(line, file=sys.stderr, flush=True)

    def done() -> None:
        if tty:
            print(file=sys.stderr)

    return show, done


def _summary_table(results: list[RunResult]) -> Table:
    rows = []
    for r in results:
        rec = load(r.path)
        rows.append((metrics(rec), run_info(rec)))
    return compare_table(compare_rows(rows))


def _one(
    protocol: Path, set_: list[str], rig: RigChoice, out: Path, flag: StopFlag
) -> RunResult:
    show, done = _progress_printer(protocol.stem)

    def notice(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    try:
        result = run_file(
            protocol, set_, rig=rig, out_dir=out, progress=show, stop_requested=flag,
            notice=notice,
        )
    finally:
        done()
    o = result.outcome
    status = "aligned" if o.aligned else o.reason
    typer.echo(f"{result.protocol.name}: {o.phase.name} ({status}) after {o.duration_s:.2f} s")
    typer.echo(f"recording: {result.path}")
    return result


RIG_HELP = "Rig file (rigs/*.toml): the robot and F/T back-ends and every hardware number."
RIG_SET_HELP = "Override a rig field, e.g. --rig-set robot.port=49939 (repeatable)."


def rig_choice(
    rig: Path | None, driver: str, rig_set: list[str], robot_ip: str = "",
    fri_port: int | None = None, ft: str = "", netft: str = "",
) -> RigChoice:
    """The rig of a command line: the device flags become overrides of rig fields."""
    overrides = list(rig_set)
    if robot_ip:
        overrides.append(f"robot.robot_ip={robot_ip!r}")
    if fri_port is not None:
        overrides.append(f"robot.port={fri_port}")
    if ft:
        overrides.append(f"ft.type={ft!r}")
    if netft:
        host, _, port = netft.rpartition(":") if ":" in netft else (netft, "", "")
        overrides.append(f"ft.host={host!r}")
        if port:
            overrides.append(f"ft.port={port}")
    return RigChoice(path=rig, overrides=tuple(overrides), driver=None if rig else driver)


@cli_errors
def run(
    protocol: Path = typer.Argument(..., help="Run protocol TOML (protocols/method*.toml)."),
    rig: Path | None = typer.Option(None, "--rig", help=RIG_HELP),
    driver: str = typer.Option(
        "sim", "--driver", help=f"Without --rig: the built-in rig of {', '.join(DRIVERS)}."
    ),
    set_: list[str] = typer.Option([], "--set", help=SET_HELP),
    rig_set: list[str] = typer.Option([], "--rig-set", help=RIG_SET_HELP),
    out: Path = typer.Option(Path("runs"), "--out", help="Directory for the MCAP recording."),
    fri_port: int | None = typer.Option(
        None, "--fri-port", help="Rig robot.port: local UDP port for FRI (0 = any)."
    ),
    robot_ip: str = typer.Option("", "--robot-ip", help="Rig robot.robot_ip: the KRC's address."),
    ft: str = typer.Option("", "--ft", help=f"Rig ft.type: {', '.join(FT_SOURCES)}."),
    netft: str = typer.Option("", "--netft", help="Rig ft.host and ft.port as HOST[:PORT]."),
) -> None:
    """Run one experiment; print a summary and the path of its recording."""
    choice = rig_choice(rig, driver, rig_set, robot_ip, fri_port, ft, netft)
    with stop_signals(StopFlag()) as flag:
        result = _one(protocol, set_, choice, out, flag)
    console.print(_summary_table([result]))
    code = flag.exit_code()
    if code is not None:
        raise typer.Exit(code)
    if result.outcome.phase == Phase.ABORT:
        raise typer.Exit(3)


@cli_errors
def campaign(
    campaign_file: Path = typer.Argument(..., help="Campaign TOML (protocols/paper.toml)."),
    rig: Path | None = typer.Option(None, "--rig", help=RIG_HELP),
    driver: str = typer.Option(
        "sim", "--driver", help=f"Without --rig: the built-in rig of {', '.join(DRIVERS)}."
    ),
    set_: list[str] = typer.Option([], "--set", help="Override in every run's protocol."),
    rig_set: list[str] = typer.Option([], "--rig-set", help=RIG_SET_HELP),
    out: Path = typer.Option(Path("runs"), "--out", help="Directory for recordings and figures."),
) -> None:
    """Run several protocols and compare them with the paper's Table (res_par)."""
    camp = load_campaign(campaign_file)
    choice = rig_choice(rig, driver, rig_set)
    results: list[RunResult] = []
    with stop_signals(StopFlag()) as flag:
        for entry in camp.runs:
            if flag():
                break
            results.append(
                _one(campaign_file.parent / entry.protocol, [*entry.set, *set_], choice, out, flag)
            )
    _paper_table(results)
    console.print(_summary_table(results))
    figures = _campaign_figures(results, out / f"{camp.name}-figures")
    for path in figures:
        typer.echo(f"figure: {path}")
    code = flag.exit_code()
    if code is not None:
        raise typer.Exit(code)


def _paper_table(results: list[RunResult]) -> None:
    columns = ("run", "f_ref [N]", "k_xp", "k_yp", "paper contact [s]", "ours contact [s]",
               "paper end [s]", "ours aligned [s]", "ours breaks", "ours end")
    rows = []
    for r in results:
        paper = r.protocol.paper
        start = paper.get("start_s")
        rec = load(r.path)
        m = metrics(rec)

        def rel(key: str, paper: dict[str, float | str] = paper, start: object = start) -> str:
            v = paper.get(key)
            if isinstance(v, float) and isinstance(start, float):
                return f"{v - start:.1f}"
            return "-" if v is None else str(v)

        align = r.protocol.align
        k_ri = getattr(align, "k_ri", None)
        f_ref = getattr(align, "f_ref", None)
        force = controllers.tracks_force_reference(r.protocol.method)
        rows.append((
            r.protocol.name,
            f"{f_ref[2]:g}" if force and f_ref is not None else "-",
            f"{k_ri[3]:g}" if k_ri is not None else "-",
            f"{k_ri[1]:g}" if k_ri is not None else "-",
            rel("contact_s"),
            "-" if m.first_contact_s is None else f"{m.first_contact_s:.1f}",
            rel("end_s"),
            "-" if m.alignment_time_s is None else f"{m.alignment_time_s:.1f}",
            str(m.contact_breaks),
            r.outcome.reason or r.outcome.phase.name,
        ))
    title = "paper Table res_par vs this run (times since the start of the experiment)"
    console.print(plain_table(title, columns, rows))


def _campaign_figures(results: list[RunResult], out_dir: Path) -> list[Path]:
    from ffexp.analysis import campaign_figure

    if not results:
        return []
    out_dir.mkdir(parents=True, exist_ok=True)
    recs = [(r.protocol.name, load(r.path)) for r in results]
    paths: list[Path] = []
    try:
        fig = campaign_figure(recs)
        path = out_dir / "exp_all_wrench.png"
        fig.savefig(path, dpi=130)
        paths.append(path)
        for name, rec in recs:
            paths.extend(write_run_figures(rec, out_dir, name))
    except FfexpError as exc:
        typer.echo(f"warning: figures incomplete: {exc}", err=True)
    return paths
