"""The energy-gain curve: the impact protocol over the carrier's extra delay, the contact's
stiffness and the compensation, every run recorded and analysed, one CSV table and one
figure of the measured restitution beside the delayed unilateral contact's and the free
body's (``ffexp hil-sweep``)."""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any

from ffexp.hil.analysis import analyze_recording
from ffexp.hil.protocol import HilProtocol
from ffexp.hil.record import record_impact, run_protocol
from ffexp.recording import load

__all__ = ["COLUMNS", "curve_figure", "sweep"]

#: The table's columns (the sweep's knobs, then the analysis' keys).
COLUMNS = ("compensation", "contact_stiffness_npm", "extra_delay_cycles", "loop_delay_s",
           "wn_tau", "restitution", "true_restitution", "reference_restitution",
           "linear_restitution", "critical_delay_s", "dissipated_j", "path_error_m",
           "contact_duration_s", "true_contact_duration_s", "peak_force_n",
           "true_peak_force_n", "carrier_held", "file")


def sweep(protocol: HilProtocol, out: Path, delays: list[int], stiffnesses: list[float],
          compensations: list[str]) -> list[dict[str, Any]]:
    """Run every combination; write ``out/<...>.mcap`` and ``out/hil_sweep.csv``."""
    rows = []
    for comp in compensations:
        for k in stiffnesses:
            for d in delays:
                sets = (f"carrier.compensation={comp}", f"contact.stiffness={k}",
                        f"carrier.extra_delay_cycles={d}")
                path = out / f"{protocol.name}-{comp}-k{k:g}-d{d}.mcap"
                path.unlink(missing_ok=True)
                a = analyze_recording(load(record_impact(run_protocol(protocol, sets), path)))
                tau = a["loop_delay_s"]
                wn_tau = None if tau is None else math.sqrt(k / a["effective_mass_kg"]) * tau
                rows.append({**{c: a.get(c) for c in COLUMNS}, "wn_tau": wn_tau,
                             "file": path.name})
    with (out / "hil_sweep.csv").open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=COLUMNS)
        w.writeheader()
        w.writerows(rows)
    return rows


def curve_figure(rows: list[dict[str, Any]], path: Path) -> Path:
    """Restitution over ``w_n tau``: one panel per stiffness; measured (markers, a cross
    where the carrier held), the reference (line), the linear form (dashed), the free
    body (dotted)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    stiff = sorted({r["contact_stiffness_npm"] for r in rows})
    fig, axes = plt.subplots(1, len(stiff), figsize=(4.2 * len(stiff), 3.6), squeeze=False,
                             sharey=True)
    marks = {"none": "o", "passivity": "s", "compliance": "^"}
    for ax, k in zip(axes[0], stiff, strict=True):
        ref = sorted((r["loop_delay_s"], r["reference_restitution"], r["linear_restitution"],
                      r["wn_tau"]) for r in rows
                     if r["contact_stiffness_npm"] == k and r["compensation"] == "none")
        ax.plot([x[3] for x in ref], [x[1] for x in ref], "k-", lw=1,
                label="delayed contact (reference)")
        ax.plot([x[3] for x in ref], [x[2] for x in ref], "k--", lw=0.8, label="linear form")
        for comp, mark in marks.items():
            pts = [r for r in rows if r["contact_stiffness_npm"] == k
                   and r["compensation"] == comp]
            if not pts:
                continue
            by_d = {r["extra_delay_cycles"]: r for r in rows if r["contact_stiffness_npm"] == k
                    and r["compensation"] == "none"}
            xs = [by_d[r["extra_delay_cycles"]]["wn_tau"] for r in pts]  # the loop's own delay
            ok = [(x, r["restitution"]) for x, r in zip(xs, pts, strict=True)
                  if r["restitution"] is not None]
            held = [x for x, r in zip(xs, pts, strict=True) if r["restitution"] is None]
            line = ax.plot([p[0] for p in ok], [p[1] for p in ok], mark, ms=5,
                           label=f"measured, {comp}")[0]
            if held:
                ax.plot(held, [1.0] * len(held), "x", color=line.get_color(), ms=7,
                        label=f"held (unstable), {comp}")
        ax.axhline(pts[0]["true_restitution"] if pts else 0.0, color="grey", ls=":",
                   label="free body")
        ax.axvline(0.3, color="grey", lw=0.5)
        ax.set_title(f"contact {k:g} N/m")
        ax.set_xlabel("w_n tau (loop delay without compensation)")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("restitution")
    axes[0][-1].legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
