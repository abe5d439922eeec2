"""``ffexp simulate``: the paper's Section III model and its sweeps."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import typer

from ffexp.cli._common import CONTEXT_SETTINGS, cli_errors, new_file

if TYPE_CHECKING:
    from ffexp.contact1dof import ContactParams, Summary

app = typer.Typer(
    help="Simulations of the paper's Section III contact model.",
    no_args_is_help=True,
    context_settings=CONTEXT_SETTINGS,
)

#: The defaults are the model's (ffexp.contact1dof.ContactParams: the paper's sim2).
_D = " Default: the paper's Table, column sim2."
#: Which sweep summary columns a narrow terminal drops first (highest first).
_SWEEP_PRIORITY = {
    "value": 0, "peak_F_c": 0, "contact_broke": 0, "t_peak": 1, "break_time": 1,
    "min_F_c": 2, "settling_time": 3, "final_v_t": 4, "final_v_i": 5,
}


@app.command("contact-1dof")
@cli_errors
def contact_1dof(
    m_ri: float | None = typer.Option(None, "--m-ri", help="Manipulator mass (kg)." + _D),
    m_t: float | None = typer.Option(None, "--m-t", help="Target mass (kg)." + _D),
    k_ri: float | None = typer.Option(None, "--k-ri", help="Manipulator stiffness (N/m)." + _D),
    b_ri: float | None = typer.Option(None, "--b-ri", help="Manipulator damping (N s/m)." + _D),
    k_c: float | None = typer.Option(None, "--k-c", help="Contact stiffness (N/m)." + _D),
    b_c: float | None = typer.Option(None, "--b-c", help="Contact damping (N s/m)." + _D),
    v0: float | None = typer.Option(None, "--v0", help="Initial manipulator velocity (m/s)." + _D),
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
    from pydantic import ValidationError

    from ffexp.contact1dof import MAX_SAMPLES, ContactParams, simulate, summarize
    from ffexp.contact1dof.sweep import write_trajectory_csv as write_csv
    from ffexp.errors import ConfigError

    given = {"m_ri": m_ri, "m_t": m_t, "k_ri": k_ri, "b_ri": b_ri, "k_c": k_c, "b_c": b_c,
             "v0": v0}
    try:
        params = ContactParams(
            **{k: v for k, v in given.items() if v is not None}, unilateral=unilateral,
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
    new_file("--csv", csv_path)
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
    set_: list[str] = typer.Option([], "--set", help="Override a field of the sweep protocol, "
                                   "e.g. --set sweep.values=[1,2] (repeatable)."),
) -> None:
    """Run a Section III sweep and write its F_c(t) figure (PNG, SVG) and CSVs.

    Never overwrites: files whose names are taken in OUT get -1, -2, ...
    """
    from ffexp.cli.progress import Steps
    from ffexp.cli.tables import Column, console, fitted_table
    from ffexp.contact1dof.sweep import (
        SUMMARY_COLUMNS,
        SweepProtocol,
        run_sweep,
        summary_rows,
        write_outputs,
    )
    from ffexp.errors import ConfigError
    from ffexp.filekind import load_as

    if out.exists() and not out.is_dir():
        raise ConfigError("--out", str(out), "exists and is not a directory")
    proto = load_as(SweepProtocol, protocol, set_, "sweep protocol")
    with Steps() as steps:
        with steps.step(f"sweep {proto.name}"):
            results = run_sweep(proto)
        with steps.step("writing figures and CSVs"):
            try:
                paths = write_outputs(proto, results, out)
            except OSError as exc:
                raise ConfigError(str(out), "", f"cannot write: {exc.strerror}") from None
    title = f"{proto.name}: {proto.description}".rstrip(": ")
    con = console()
    cols = [Column(c, c, _SWEEP_PRIORITY.get(c, 5)) for c in SUMMARY_COLUMNS]
    rows = [dict(zip(SUMMARY_COLUMNS, r, strict=True)) for r in summary_rows(results)]
    con.print(fitted_table(con, title, cols, rows))
    for path in paths:
        typer.echo(f"wrote {path}")
