"""``ffexp simulate``: the paper's Section III model and its sweeps."""

from __future__ import annotations

from pathlib import Path

import typer
from pydantic import ValidationError
from rich.console import Console

from drivers.config import load_model
from ffexp.cli._common import SET_HELP, cli_errors, plain_table
from ffexp.contact1dof import MAX_SAMPLES, ContactParams, Summary, simulate, summarize
from ffexp.errors import ConfigError
from ffexp.sweep import SUMMARY_COLUMNS, SweepProtocol, run_sweep, summary_rows, write_outputs
from ffexp.sweep import write_trajectory_csv as write_csv

app = typer.Typer(
    help="Simulations of the paper's Section III contact model.",
    no_args_is_help=True,
)

_D = ContactParams()


@app.command("contact-1dof")
@cli_errors
def contact_1dof(
    m_ri: float = typer.Option(_D.m_ri, "--m-ri", help="Manipulator mass (kg)."),
    m_t: float = typer.Option(_D.m_t, "--m-t", help="Target mass (kg)."),
    k_ri: float = typer.Option(_D.k_ri, "--k-ri", help="Manipulator stiffness (N/m)."),
    b_ri: float = typer.Option(_D.b_ri, "--b-ri", help="Manipulator damping (N s/m)."),
    k_c: float = typer.Option(_D.k_c, "--k-c", help="Contact stiffness (N/m)."),
    b_c: float = typer.Option(_D.b_c, "--b-c", help="Contact damping (N s/m)."),
    v0: float = typer.Option(_D.v0, "--v0", help="Initial manipulator velocity (m/s)."),
    duration: float = typer.Option(3.0, "--duration", help="Simulated time (s)."),
    dt: float = typer.Option(0.001, "--dt", help="Output sample period (s)."),
    unilateral: bool = typer.Option(
        False, "--unilateral", help="Contact only pushes (F_c clamped at 0)."
    ),
    csv_path: Path | None = typer.Option(
        None, "--csv", help="Write t,x_i,v_i,x_t,v_t,p,F_c to this CSV file."
    ),
) -> None:
    """One run of the 1-DOF contact model (defaults: the paper's Table, sim2, k_ri = 0)."""
    try:
        params = ContactParams(
            m_ri=m_ri, m_t=m_t, k_ri=k_ri, b_ri=b_ri, k_c=k_c, b_c=b_c, v0=v0,
            unilateral=unilateral,
        )
    except ValidationError as exc:
        err = exc.errors()[0]
        name = "--" + str(err["loc"][0]).replace("_", "-")
        raise ConfigError("options", name, err["msg"]) from None
    if not duration > 0.0:
        raise ConfigError("options", "--duration", f"must be > 0 s, got {duration}")
    if not 0.0 < dt <= duration:
        raise ConfigError("options", "--dt", f"must be > 0 s and <= --duration, got {dt}")
    if round(duration / dt) + 1 > MAX_SAMPLES:
        raise ConfigError("options", "--dt", f"{duration / dt:.3g} samples is too many: raise it")
    traj = simulate(params, duration, dt)
    if csv_path is not None:
        try:
            write_csv(csv_path, traj)
        except OSError as exc:
            raise ConfigError(str(csv_path), "", f"cannot write: {exc.strerror}") from None
    _print_summary(summarize(traj), params)
    if csv_path is not None:
        typer.echo(f"wrote {csv_path}")


def _print_summary(s: Summary, params: ContactParams) -> None:
    def opt(x: float | None) -> str:
        return "never" if x is None else f"{x:.3f} s"

    model = "unilateral" if params.unilateral else "penalty (bilateral)"
    typer.echo(f"contact model: {model}; m_ri/m_t = {params.m_ri / params.m_t:.3g}")
    typer.echo(f"peak F_c:      {s.peak_f_c_n:.4g} N at {s.t_peak_s:.3f} s")
    typer.echo(f"min F_c:       {s.min_f_c_n:.4g} N")
    broke = f"yes, at {s.break_time_s:.3f} s" if s.break_time_s is not None else "no"
    typer.echo(f"contact broke: {broke}")
    typer.echo(f"final v_i:     {s.final_v_i_mps:.4g} m/s")
    typer.echo(f"final v_t:     {s.final_v_t_mps:.4g} m/s")
    typer.echo(f"settling time: {opt(s.settling_time_s)} (F_c within 2 % of its peak)")


@app.command("sweep")
@cli_errors
def sweep(
    protocol: Path = typer.Argument(..., help="Sweep protocol TOML (protocols/sec3_*.toml)."),
    out: Path = typer.Option(Path("runs"), "--out", help="Output directory."),
    set_: list[str] = typer.Option([], "--set", help=SET_HELP),
) -> None:
    """Run a Section III sweep and write its F_c(t) figure (PNG, SVG) and CSVs."""
    proto = load_model(SweepProtocol, protocol, set_)
    results = run_sweep(proto)
    try:
        paths = write_outputs(proto, results, out)
    except OSError as exc:
        raise ConfigError(str(out), "", f"cannot write: {exc.strerror}") from None
    title = f"{proto.name}: {proto.description}".rstrip(": ")
    Console(width=160).print(plain_table(title, SUMMARY_COLUMNS, summary_rows(results)))
    for path in paths:
        typer.echo(f"wrote {path}")
