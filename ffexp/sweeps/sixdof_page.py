"""The 6-DOF study's figures and tables from its sweep directories.

    python -m ffexp.sweeps.sixdof_page STUDY_DIR FIGURES_DIR

``STUDY_DIR`` holds one ``ffexp sweep`` directory per question, named
``<question>-<method>`` (``mass-method1``, ``base-method2``, ...: the commands are
on the results page, docs/results/). Every run's metrics are computed again from
its recording (``ffexp analyze``), so the page follows the analysis of today's
code; lean sweeps (``ffexp sweep --lean``) serve it as well as full ones (a lean
file holds every topic the metrics read). Prints one markdown table per question
and writes one figure per question (PNG) into ``FIGURES_DIR``.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Any

METHODS = ("method1", "method2", "method3", "admittance")
LABELS = {"method1": "Method I", "method2": "Method II", "method3": "Method III",
          "admittance": "admittance"}
#: question -> (varied key, title, x label)
QUESTIONS = {
    "mass": ("scene.target.mass", "target mass", "target mass [kg]"),
    "lateral": ("scene.target.lateral", "lateral offset", "lateral offset [m]"),
    "pitch": ("scene.target.pitch_deg", "tilt of the funnel axis", "pitch [deg]"),
    "drift": ("scene.target.drift_mps", "initial drift along the approach", "drift vx [m/s]"),
    "tumble": ("scene.target.tumble_radps", "initial tumble", "tumble"),
    "base": ("scene.base.mode", "the chaser's base mode", "base mode"),
    "gains": ("scene.base.attitude_kp", "attitude gain (attitude held)", "kp [N m/rad]"),
}


def _rows(study: Path, question: str) -> list[dict[str, Any]]:
    """Every run of the question's sweeps: the varied value, the method and its metrics."""
    import json

    from ffexp.analysis import metrics
    from ffexp.recording import load

    key = QUESTIONS[question][0]
    out = []
    for method in METHODS:
        sweep = study / f"{question}-{method}"
        if not sweep.is_dir():
            continue
        import csv

        results = sweep / "results.csv"
        if not results.exists():
            continue
        with results.open(newline="") as fh:  # the sweep's own runs, its latest plan
            paths = [r["path"] for r in csv.DictReader(fh) if r.get("path")]
        for rel in paths:
            mcap = sweep / rel
            row_file = mcap.parent / "row.json"
            if not mcap.exists() or not row_file.exists():
                continue
            row = json.loads(row_file.read_text())
            m = metrics(load(mcap))
            out.append({"method": method, "value": row.get(key), "aligned": m.aligned,
                        "outcome": m.outcome,
                        "aligned_s": m.alignment_time_s, "contact_s": m.first_contact_s,
                        "breaks": m.contact_breaks, "momentum": m.target_momentum_ns,
                        "impulse": m.contact_impulse_ns, "end": m.aborted or (
                            "aligned" if m.aligned else "timeout"),
                        "moved": m.target_displacement_m,
                        "base_m": m.base_max_displacement_m,
                        "base_deg": m.base_max_rotation_deg})
    order = {"free_floating": 0, "attitude_held": 1, "pose_held": 2}

    def rank(r: dict[str, Any]) -> tuple[int, Any]:
        v = r["value"]
        key = order.get(v, 0) if isinstance(v, str) else (
            [abs(x) for x in v][::-1] + v if isinstance(v, list) else v)
        return METHODS.index(r["method"]), key

    return sorted(out, key=rank)


def _text(v: Any) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "-"
    if isinstance(v, float):
        return f"{v:.3g}"
    if isinstance(v, list):
        return "[" + ", ".join(f"{x:g}" for x in v) + "]"
    return str(v).split(":")[0]


def table(rows: list[dict[str, Any]], base: bool) -> str:
    """One markdown table of a question's runs."""
    head = ["method", "value", "outcome", "end", "aligned [s]", "contact [s]", "breaks",
            "momentum [N s]", "impulse [N s]"]
    keys = ["method", "value", "outcome", "end", "aligned_s", "contact_s", "breaks",
            "momentum", "impulse"]
    if base:
        head += ["base moved [m]", "base turned [deg]"]
        keys += ["base_m", "base_deg"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [LABELS[r["method"]] if k == "method" else _text(r[k]) for k in keys]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _x(value: Any) -> float | str:
    if isinstance(value, list):
        nonzero = [v for v in value if v]
        return float(value[0]) if len(nonzero) <= 1 and value[0] else str(value)
    return value if isinstance(value, str) else float(value)


def figure(rows: list[dict[str, Any]], question: str, path: Path) -> None:
    """Imparted momentum (and the base's excursion) against the varied value, per method."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    base = question in ("base", "gains")
    fig, axes = plt.subplots(1, 2 if base else 1, figsize=(10 if base else 6, 4),
                             squeeze=False)
    title, xlabel = QUESTIONS[question][1], QUESTIONS[question][2]
    for method in METHODS:
        mine = [r for r in rows if r["method"] == method]
        if not mine:
            continue
        xs = [str(_x(r["value"])) if question in ("tumble", "base") else _x(r["value"])
              for r in mine]
        ax = axes[0][0]
        ax.plot(xs, [r["momentum"] for r in mine], "o-", label=LABELS[method])
        for x, r in zip(xs, mine, strict=True):
            if r["aligned"]:
                ax.plot([x], [r["momentum"]], "k*", markersize=12)
        if base:
            axes[0][1].plot(xs, [r["base_deg"] for r in mine], "s-", label=LABELS[method])
    ax = axes[0][0]
    ax.set_title(f"imparted momentum over {title} (* aligned)")
    ax.set_xlabel(xlabel)
    ax.set_ylabel("target momentum change [N s]")
    if question == "mass":
        masses = sorted({float(r["value"]) for r in rows})
        ax.set_xscale("log")
        ax.set_xticks(masses, [f"{m:g}" for m in masses])
        ax.minorticks_off()
    ax.legend()
    if base:
        axes[0][1].set_title("largest rotation of the base")
        axes[0][1].set_xlabel(xlabel)
        axes[0][1].set_ylabel("[deg]")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main(argv: list[str]) -> int:
    if len(argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    study, figures = Path(argv[0]), Path(argv[1])
    figures.mkdir(parents=True, exist_ok=True)
    for question in QUESTIONS:
        rows = _rows(study, question)
        if not rows:
            continue
        figure(rows, question, figures / f"sixdof-{question}.png")
        print(f"### {QUESTIONS[question][1]}\n")
        print(table(rows, question in ("base", "gains")))
        print()
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
