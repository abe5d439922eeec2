"""``ffexp run`` and ``ffexp campaign``: the paper's experiments."""

from __future__ import annotations

import signal
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from types import FrameType

import typer
from rich.console import Console
from rich.table import Table

from ffexp.analysis import compare_rows, metrics, run_info, write_run_figures
from ffexp.cli._common import SET_HELP, cli_errors, plain_table
from ffexp.cli.records import compare_table
from ffexp.errors import FfexpError
from ffexp.experiment import DRIVERS, FT_SOURCES, LinkOptions, RunResult, load_campaign, run_file
from ffexp.recording import load
from ffexp.runner import Phase, Progress

console = Console(width=170)


class _StopFlag:
    """Set by SIGINT/SIGTERM; the runner polls it and stops safely."""

    def __init__(self) -> None:
        self.signum: int | None = None

    def __call__(self) -> bool:
        return self.signum is not None

    def handle(self, signum: int, _frame: FrameType | None) -> None:
        if self.signum is not None:  # second signal: give up waiting
            raise KeyboardInterrupt
        self.signum = signum


@contextmanager
def _signals(flag: _StopFlag) -> Iterator[None]:
    old = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    for s in old:
        signal.signal(s, flag.handle)
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)


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
    protocol: Path, set_: list[str], driver: str, out: Path, flag: _StopFlag,
    link: LinkOptions | None = None,
) -> RunResult:
    show, done = _progress_printer(protocol.stem)

    def notice(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    try:
        result = run_file(
            protocol, set_, driver=driver, out_dir=out, progress=show, stop_requested=flag,
            link=link, notice=notice,
        )
    finally:
        done()
    o = result.outcome
    status = "aligned" if o.aligned else o.reason
    typer.echo(f"{result.protocol.name}: {o.phase.name} ({status}) after {o.duration_s:.2f} s")
    typer.echo(f"recording: {result.path}")
    return result


@cli_errors
def run(
    protocol: Path = typer.Argument(..., help="Run protocol TOML (protocols/method*.toml)."),
    driver: str = typer.Option("sim", "--driver", help=f"Robot back-end: {', '.join(DRIVERS)}."),
    set_: list[str] = typer.Option([], "--set", help=SET_HELP),
    out: Path = typer.Option(Path("runs"), "--out", help="Directory for the MCAP recording."),
    fri_port: int = typer.Option(
        49938, "--fri-port", help="--driver fri: local UDP port (FRISOCK on the KRC; 0 = any)."
    ),
    robot_ip: str = typer.Option(
        "", "--robot-ip", help="--driver fri: the KRC's address; other senders are ignored."
    ),
    ft: str = typer.Option(
        "auto", "--ft",
        help=f"F/T source: {', '.join(FT_SOURCES)} (auto: sim for --driver sim, netft for fri).",
    ),
    netft: str = typer.Option(
        "", "--netft", help="--ft netft: the box as HOST:PORT (default ROBOT_IP:49152)."
    ),
) -> None:
    """Run one experiment; print a summary and the path of its recording."""
    flag = _StopFlag()
    link = LinkOptions(robot_ip=robot_ip or None, fri_port=fri_port, ft=ft, netft=netft or None)
    with _signals(flag):
        result = _one(protocol, set_, driver, out, flag, link)
    console.print(_summary_table([result]))
    if flag.signum is not None:
        raise typer.Exit(128 + flag.signum)
    if result.outcome.phase == Phase.ABORT:
        raise typer.Exit(3)


@cli_errors
def campaign(
    campaign_file: Path = typer.Argument(..., help="Campaign TOML (protocols/paper.toml)."),
    driver: str = typer.Option("sim", "--driver", help=f"Robot back-end: {', '.join(DRIVERS)}."),
    set_: list[str] = typer.Option([], "--set", help="Override in every run's protocol."),
    out: Path = typer.Option(Path("runs"), "--out", help="Directory for recordings and figures."),
) -> None:
    """Run several protocols and compare them with the paper's Table (res_par)."""
    camp = load_campaign(campaign_file)
    flag = _StopFlag()
    results: list[RunResult] = []
    with _signals(flag):
        for entry in camp.runs:
            if flag():
                break
            results.append(
                _one(campaign_file.parent / entry.protocol, [*entry.set, *set_], driver, out, flag)
            )
    _paper_table(results)
    console.print(_summary_table(results))
    figures = _campaign_figures(results, out / f"{camp.name}-figures")
    for path in figures:
        typer.echo(f"figure: {path}")
    if flag.signum is not None:
        raise typer.Exit(128 + flag.signum)


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

        k_ri = r.protocol.align.k_ri
        force = r.protocol.method != "impedance"
        rows.append((
            r.protocol.name,
            f"{r.protocol.align.f_ref[2]:g}" if force else "-",
            f"{k_ri[3]:g}" if force else "-",
            f"{k_ri[1]:g}" if force else "-",
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
