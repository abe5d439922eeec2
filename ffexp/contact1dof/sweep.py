"""Parameter sweeps of the Section III model (the paper's Fig. 3).

A sweep protocol (TOML) names the base model parameters, the time grid, the
parameter to sweep and its values. :func:`run_sweep` runs the model once per
value; :func:`write_outputs` writes the CSVs and the F_c(t) figure.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np
from pydantic import Field, ValidationError, model_validator

from drivers.config import StrictModel
from ffexp.contact1dof import COLUMNS, ContactParams, Summary, Trajectory, simulate, summarize

if TYPE_CHECKING:
    from matplotlib.figure import Figure

#: Parameters a sweep can vary; ``mass_ratio`` sets ``m_ri = value * m_t``.
SweepParameter = Literal["mass_ratio", "m_ri", "m_t", "k_ri", "b_ri", "k_c", "b_c", "v0"]

_UNITS: dict[str, str] = {
    "mass_ratio": "",
    "m_ri": "kg",
    "m_t": "kg",
    "k_ri": "N/m",
    "b_ri": "N s/m",
    "k_c": "N/m",
    "b_c": "N s/m",
    "v0": "m/s",
}
_SYMBOLS: dict[str, str] = {
    "mass_ratio": "m_ri/m_t",
    "m_ri": "m_ri",
    "m_t": "m_t",
    "k_ri": "k_ri",
    "b_ri": "b_ri",
    "k_c": "k_c",
    "b_c": "b_c",
    "v0": "v0",
}


class TimeGrid(StrictModel):
    """Simulated duration and output sample period."""

    duration_s: float = Field(3.0, gt=0)
    dt_s: float = Field(0.001, gt=0)


class SweepSpec(StrictModel):
    """What to vary: one model parameter over a list of values."""

    parameter: SweepParameter
    values: list[float] = Field(min_length=1)


class SweepProtocol(StrictModel):
    """A Section III sweep: ``protocols/sec3_*.toml``."""

    name: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_.-]+$")
    description: str = ""
    model: ContactParams = ContactParams()
    time: TimeGrid = TimeGrid()
    sweep: SweepSpec

    @model_validator(mode="after")
    def _values_make_valid_models(self) -> SweepProtocol:
        for value in self.sweep.values:
            try:
                params_for(self.model, self.sweep.parameter, value)
            except ValidationError as exc:
                err = exc.errors()[0]
                field = ".".join(str(p) for p in err["loc"])
                raise ValueError(
                    f"sweep.values: {value:g} gives model.{field}: {err['msg']}"
                ) from None
        return self


def params_for(base: ContactParams, parameter: SweepParameter, value: float) -> ContactParams:
    """The model parameters for one sweep value (validated)."""
    if parameter == "mass_ratio":
        update = {"m_ri": value * base.m_t}
    else:
        update = {parameter: value}
    return ContactParams.model_validate(base.model_dump() | update)


@dataclass(frozen=True)
class SweepResult:
    """One run of a sweep."""

    value: float
    params: ContactParams
    trajectory: Trajectory
    summary: Summary


def run_sweep(protocol: SweepProtocol) -> list[SweepResult]:
    """Run the model for every value of the sweep, in the order given."""
    results = []
    for value in protocol.sweep.values:
        params = params_for(protocol.model, protocol.sweep.parameter, value)
        traj = simulate(params, protocol.time.duration_s, protocol.time.dt_s)
        results.append(SweepResult(value, params, traj, summarize(traj)))
    return results


def value_label(parameter: SweepParameter, value: float) -> str:
    """Legend text for one sweep value, with its unit."""
    unit = _UNITS[parameter]
    return f"{_SYMBOLS[parameter]} = {value:g}" + (f" {unit}" if unit else "")


SUMMARY_COLUMNS = (
    "value",
    "m_ri",
    "m_t",
    "k_ri",
    "b_ri",
    "peak_F_c",
    "t_peak",
    "min_F_c",
    "contact_broke",
    "break_time",
    "settling_time",
    "final_v_i",
    "final_v_t",
)


def summary_rows(results: list[SweepResult]) -> list[list[str]]:
    """The per-value summary as text rows in :data:`SUMMARY_COLUMNS` order."""

    def opt(x: float | None) -> str:
        return "" if x is None else f"{x:.6g}"

    rows = []
    for r in results:
        s = r.summary
        rows.append(
            [
                f"{r.value:g}",
                f"{r.params.m_ri:g}",
                f"{r.params.m_t:g}",
                f"{r.params.k_ri:g}",
                f"{r.params.b_ri:g}",
                f"{s.peak_f_c_n:.6g}",
                f"{s.t_peak_s:.6g}",
                f"{s.min_f_c_n:.6g}",
                str(s.contact_broke).lower(),
                opt(s.break_time_s),
                opt(s.settling_time_s),
                f"{s.final_v_i_mps:.6g}",
                f"{s.final_v_t_mps:.6g}",
            ]
        )
    return rows


def write_trajectory_csv(path: Path, traj: Trajectory) -> None:
    """One run as CSV with header ``t,x_i,v_i,x_t,v_t,p,F_c`` (SI units)."""
    header = ",".join(COLUMNS)
    np.savetxt(path, traj.table(), delimiter=",", header=header, comments="", fmt="%.10g")


def write_outputs(protocol: SweepProtocol, results: list[SweepResult], out_dir: Path) -> list[Path]:
    """Write ``<name>.csv`` (all runs, long format), ``<name>_summary.csv``,
    ``<name>.png`` and ``<name>.svg`` into ``out_dir``; return the paths.

    Never overwrites: if any of the four names is taken, all four get the
    first free ``-1``, ``-2``, ... (:func:`ffexp.naming.unique_stem`).
    """
    from ffexp import figures
    from ffexp.naming import unique_stem

    out_dir.mkdir(parents=True, exist_ok=True)
    stem = unique_stem(out_dir, protocol.name, (".csv", "_summary.csv", ".png", ".svg"))
    data_csv = out_dir / f"{stem}.csv"
    with data_csv.open("w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow([protocol.sweep.parameter, *COLUMNS])
        for r in results:
            table = r.trajectory.table()
            for row in table:
                writer.writerow([f"{r.value:g}", *(f"{x:.10g}" for x in row)])
    summary_csv = out_dir / f"{stem}_summary.csv"
    with summary_csv.open("w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(SUMMARY_COLUMNS)
        writer.writerows(summary_rows(results))
    with figures.style():
        png, svg = figures.save(plot_sweep(protocol, results), out_dir, stem)
    return [png, svg, data_csv, summary_csv]


def plot_sweep(protocol: SweepProtocol, results: list[SweepResult]) -> Figure:
    """F_c(t) per swept value, with the zero line that marks a contact break
    (call inside :func:`ffexp.figures.style`)."""
    from ffexp.figures import new_figure  # matplotlib: slow, and only plots need it

    fig = new_figure(7.0, 4.2)
    ax = fig.add_subplot()
    for r in results:
        label = value_label(protocol.sweep.parameter, r.value)
        ax.plot(r.trajectory.t_s, r.trajectory.f_c, label=label)
    ax.axhline(0.0, color="black", linewidth=0.8, linestyle="--", label="F_c = 0 (break below)")
    ax.set_xlabel("time t [s]")
    ax.set_ylabel("contact force F_c [N]")
    fixed = ", ".join(
        f"{k}={getattr(results[0].params, k):g}"
        for k in ("m_t", "m_ri", "k_ri", "b_ri", "k_c", "b_c", "v0")
        if not _varies(results, k)
    )
    ax.set_title(f"{protocol.name}: F_c(t)\n{fixed}")
    ax.legend(title=_SYMBOLS[protocol.sweep.parameter])
    return fig


def _varies(results: list[SweepResult], name: str) -> bool:
    values = {getattr(r.params, name) for r in results}
    return len(values) > 1
