"""What a calibration reports: a table per parameter, residuals, validation, figures, HTML.

:func:`summary` makes the rows every output shares (terminal, JSON, HTML);
:func:`write_report` writes ``calibration.json``, one figure per recording
(recorded against simulated at the start values and at the result) and
``calibration.html`` (figures embedded) into a directory, and the tables as CSV, so
that ``ffexp report DIR`` also shows it all in the project's own report page.
"""

from __future__ import annotations

import base64
import csv
import html
import io
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ffexp.calibrate.inputs import ReplayInput
from ffexp.calibrate.residuals import SIGNALS, UNITS, Comparison, ft_on_recorded, outcomes
from ffexp.calibrate.resim import Trace
from ffexp.calibrate.result import FitResult


def _g(v: float) -> str:
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.4g}"


def result_dict(res: FitResult) -> dict[str, Any]:
    """The JSON form of a result (without traces)."""
    def comps(cs: list[Comparison]) -> list[dict[str, Any]]:
        return [{"rms": c.rms, "bias": c.bias.tolist(), "noise_floor_n": c.noise_floor_n,
                 "cost": c.cost} for c in cs]

    return {
        "values": res.values, "converged": res.converged, "ft_shift_samples": res.ft_shift,
        "condition": res.condition, "correlation": res.correlation,
        "correlation_keys": res.corr_keys,
        "estimates": [vars(e) for e in res.estimates], "stages": [vars(s) for s in res.stages],
        "start": {k: comps(v) for k, v in res.start.items()},
        "final": {k: comps(v) for k, v in res.final.items()},
        "rollouts": res.rollouts, "elapsed_s": res.elapsed_s, "start_shift": res.start_shift,
        "consistent": res.consistent, "inconsistent": res.inconsistent,
        "warnings": res.warnings,
    }


def parameter_rows(res: FitResult) -> list[dict[str, Any]]:
    return [{"key": e.key, "start": e.start, "value": e.value,
             "interval": f"[{_g(e.ci_lo)}, {_g(e.ci_hi)}]", "bounds": f"[{_g(e.lo)}, {_g(e.hi)}]",
             "stage": e.stage, "method": e.method,
             "identified": "yes" if e.identified else "NO", "note": e.note}
            for e in res.estimates]


def residual_rows(res: FitResult, inputs: dict[str, list[ReplayInput]]) -> list[dict[str, Any]]:
    """Per recording (fitted and held out): RMS per signal at the start and the result,
    F/T RMS over the sensor's noise floor, and whether the outcomes agree."""
    rows = []
    for name in ("fit", "holdout"):
        for inp, c0, c1, (_t0, t1) in zip(inputs.get(name, []), res.start.get(name, []),
                                          res.final.get(name, []), res.traces.get(name, []),
                                          strict=True):
            rec_o, sim_o = outcomes(inp, t1, res.ft_shift)
            row: dict[str, Any] = {"recording": inp.name, "set": name}
            for s in SIGNALS:
                row[s] = f"{_g(c0.rms[s])} -> {_g(c1.rms[s])}"
            row["F/T / noise"] = _g(c1.rms["force"] / c1.noise_floor_n)
            row["outcome (recorded | simulated)"] = f"{rec_o.text()} | {sim_o.text()}"
            row["agree"] = "yes" if rec_o.agrees(sim_o) else "NO"
            rows.append(row)
    return rows


def _figure(inp: ReplayInput, start: Trace, final: Trace, shift0: int, shift: int,
            bias0: np.ndarray, bias: np.ndarray) -> bytes:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    has_target = len(inp.target_t_s) > 0
    fig, axes = plt.subplots(3 + has_target, 1, figsize=(9, 2.3 * (3 + has_target)),
                             sharex=True, constrained_layout=True)
    ax = axes[0]
    ax.plot(inp.t_s, inp.tcp[:, 0] * 1e3, "k", lw=1.2, label="recorded")
    ax.plot(start.t_s, start.tcp[:, 0] * 1e3, "C1--", lw=1, label="simulated, start")
    ax.plot(final.t_s, final.tcp[:, 0] * 1e3, "C0", lw=1, label="simulated, calibrated")
    ax.set_ylabel("TCP x [mm]")
    ax.legend(loc="best", fontsize=8)
    for ax, i, lab in ((axes[1], 2, "F/T z [N]"), (axes[2], 1, "F/T y [N]")):
        ax.plot(inp.ft_t_s, inp.ft[:, i], "k", lw=0.6)
        ax.plot(inp.ft_t_s, ft_on_recorded(inp, start, shift0)[:, i] + bias0[i], "C1--", lw=1)
        ax.plot(inp.ft_t_s, ft_on_recorded(inp, final, shift)[:, i] + bias[i], "C0", lw=1)
        ax.set_ylabel(lab)
    if has_target:
        ax = axes[3]
        ax.plot(inp.target_t_s, inp.target[:, 1] * 1e3, "k.", ms=2)
        ax.plot(start.t_s, start.target[:, 1] * 1e3, "C1--", lw=1)
        ax.plot(final.t_s, final.target[:, 1] * 1e3, "C0", lw=1)
        ax.set_ylabel("target y [mm]")
    axes[-1].set_xlabel("run time [s]")
    fig.suptitle(inp.name, fontsize=10)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    return buf.getvalue()


def _cell(value: Any) -> str:
    """A table cell for the reader: numbers to 6 significant digits (the CSV and JSON
    beside the page keep every digit)."""
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, (list, tuple)):
        return ", ".join(_cell(v) for v in value)
    return str(value)


def _table(rows: Sequence[dict[str, Any]]) -> str:
    if not rows:
        return "<p>none</p>"
    cols = list(rows[0])
    head = "".join(f"<th>{html.escape(c)}</th>" for c in cols)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(_cell(r[c]))}</td>" for c in cols)
                   + "</tr>" for r in rows)
    return f"<div class='scroll'><table><tr>{head}</tr>{body}</table></div>"


_CSS = ("body{font-family:sans-serif;margin:1.5em;max-width:1200px}"
        "table{border-collapse:collapse;font-size:13px;margin:0.5em 0}"
        "td,th{border:1px solid #bbb;padding:3px 6px;text-align:left}th{background:#eee}"
        "pre{white-space:pre-wrap;overflow-wrap:anywhere}.scroll{overflow-x:auto;max-width:100%}"
        ".warn{color:#a00}img{max-width:100%}")


def write_report(directory: Path, res: FitResult, inputs: dict[str, list[ReplayInput]],
                 header: Sequence[str], scene_path: Path | None) -> list[Path]:
    """Write ``calibration.json``, the figures and ``calibration.html`` into ``directory``."""
    directory.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    data = result_dict(res)
    data["recordings"] = {k: [str(i.path) for i in v] for k, v in inputs.items()}
    data["scene"] = str(scene_path) if scene_path else None
    (directory / "calibration.json").write_text(json.dumps(data, indent=1, default=float))
    written.append(directory / "calibration.json")
    # the tables as CSV too: `ffexp report DIR` shows them (and the figures) in its own page
    for name, rows in (("parameters", parameter_rows(res)),
                       ("residuals", residual_rows(res, inputs))):
        path = directory / f"calibration-{name}.csv"
        with path.open("w", newline="", encoding="utf-8") as fh:
            writer = csv.DictWriter(fh, fieldnames=list(rows[0]) if rows else [])
            writer.writeheader()
            writer.writerows(rows)
        written.append(path)
    shift0 = int(data.get("start_shift", res.ft_shift))
    figs: list[tuple[str, bytes]] = []
    for name in ("fit", "holdout"):
        for inp, c0, c1, (t0, t1) in zip(inputs.get(name, []), res.start.get(name, []),
                                          res.final.get(name, []), res.traces.get(name, []),
                                          strict=True):
            png = _figure(inp, t0, t1, shift0, res.ft_shift, c0.bias, c1.bias)
            path = directory / f"calibration-{name}-{inp.path.stem}.png"
            path.write_bytes(png)
            written.append(path)
            figs.append((f"{name}: {inp.name}", png))
    parts = [f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>ffexp "
             f"calibration</title><style>{_CSS}</style></head><body><h1>ffexp calibration</h1>",
             "<pre>" + html.escape("\n".join(header)) + "</pre>"]
    if not res.converged:
        parts.append("<p class='warn'>the fit did not converge: no scene was written</p>")
    parts.append("<h2>Parameters</h2>" + _table(parameter_rows(res)))
    parts.append(f"<p>conditioning of the normalised J<sup>T</sup>J: {_g(res.condition)}; "
                 "correlations:</p>")
    corr = [{"": k, **{kk: f"{v:+.3f}" for kk, v in zip(res.corr_keys, row, strict=True)}}
            for k, row in zip(res.corr_keys, res.correlation, strict=True)]
    parts.append(_table(corr))
    parts.append("<h2>Stages</h2>" + _table([vars(s) for s in res.stages]))
    if res.warnings or not res.consistent:
        lines = [*(f"not consistent with the data: {x}" for x in res.inconsistent),
                 *(f"warning: {w}" for w in res.warnings)]
        parts.append("".join(f"<p class='warn'>{html.escape(x)}</p>" for x in lines))
    units = ", ".join(f"{s} [{UNITS[s]}]" for s in SIGNALS)
    parts.append(f"<h2>Residuals and validation</h2><p>RMS of recorded minus simulated, at "
                 f"the start values -> at the result: {html.escape(units)}; held-out "
                 "recordings were not fitted to.</p>")
    parts.append(_table(residual_rows(res, inputs)))
    parts.append("<h2>Recorded and simulated</h2>")
    for alt, png in figs:
        uri = "data:image/png;base64," + base64.b64encode(png).decode()
        parts.append(f"<figure><img src='{uri}' alt='{html.escape(alt)}'>"
                     f"<figcaption>{html.escape(alt)}: black recorded, orange dashed "
                     "simulated at the start values, blue at the result</figcaption></figure>")
    parts.append("</body></html>")
    page = directory / "calibration.html"
    page.write_text("\n".join(parts), encoding="utf-8")
    written.append(page)
    return written
