"""The alignment observer against the truth: a confusion matrix over perturbed simulated runs.

    python benchmarks/observer_confusion.py [--out DIR] [--workers N] [--scenes K] [--seed S]
                                            [--source observer|settings|tracker]

Every method's protocol (Methods I case 1 and 2, II at 0.8 N and 1.5 N, III,
admittance) runs in ``K`` perturbed scenes (the target's lateral offset,
yaw, start distance and bed friction drawn uniformly around the paper's
scene, seeded) with ``alignment.source`` set to the judge under test
(default: the observer, no tracker). Each recording's final
``/alignment/verdict`` holds the judge's label beside the simulator's truth
verdict; the script prints the confusion matrix (rows: truth, columns: the
judge's label) and every run that the judge called aligned while the truth
says not aligned, and writes ``confusion.csv`` (one line per run) to ``--out``.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RUNS: dict[str, tuple[str, list[str]]] = {
    "I-1": ("method1_case1.toml", []),
    "I-2": ("method1_case2.toml", []),
    "II-0.8": ("method2.toml", ["align.f_ref=[0.0, 0.0, 0.8, 0.0, 0.0, 0.0]"]),
    "II-1.5": ("method2.toml", []),
    "III": ("method3_impedance.toml", []),
    "adm": ("admittance.toml", []),
}


def scenes(k: int, seed: int) -> list[list[str]]:
    """``k`` perturbed scenes as scene overrides (paper scene: 12 mm, 8 deg, 30 mm)."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(k):
        out.append([
            f"target.lateral={rng.uniform(0.004, 0.020):.4f}",
            f"target.yaw_deg={rng.uniform(3.0, 12.0):.2f}",
            f"target.distance={rng.uniform(0.015, 0.045):.4f}",
            f"target.mu={rng.uniform(0.005, 0.012):.4f}",
        ])
    return out


def one(job: tuple[str, int, list[str], str, str]) -> dict[str, str]:
    from ffexp.experiment import run_file
    from ffexp.rig_choice import RigChoice

    name, k, scene_set, source, out = job
    path, extra = RUNS[name]
    overrides = [*extra, f"alignment.source={source}", f"scene.set={json.dumps(scene_set)}"]
    rig = RigChoice(overrides=("tracker.type='sim'",)) if source == "tracker" else None
    res = run_file(ROOT / "protocols" / path, overrides, rig=rig, out_dir=Path(out) / name)
    verdict = final_verdict(res.path)
    return {"run": name, "scene": str(k), "set": " ".join(scene_set),
            "label": verdict.get("label", "?"), "truth": verdict.get("truth", "?"),
            "truth_end": truth_at_end(res.path),
            "source": verdict.get("source", "?"), "end": str(res.outcome.reason),
            "breaks": str(res.outcome.breaks), "path": str(res.path)}


def truth_at_end(path: Path) -> str:
    """The truth's placement at the run's last cycle, with the protocol's tolerances."""
    import math

    from ffexp.recording import load
    from ffexp.task import Alignment

    a = Alignment()
    tr = load(path).topic("/task/funnel")
    ok = (abs(float(tr["lateral"][-1])) <= a.lateral_tol_m
          and abs(math.degrees(float(tr["yaw"][-1]))) <= a.yaw_tol_deg
          and float(tr["insertion"][-1]) >= a.min_insertion_m)
    return "aligned" if ok else "not aligned"


def final_verdict(path: Path) -> dict[str, str]:
    """The recording's final ``/alignment/verdict`` ({} when there is none)."""
    from ffexp.analysis import final_verdict as final_of
    from ffexp.recording import load

    return {k: v for k, v in final_of(load(path)).items() if isinstance(v, str)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("runs/observer-confusion"))
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--scenes", type=int, default=8)
    ap.add_argument("--seed", type=int, default=12)
    ap.add_argument("--source", default="observer", choices=["observer", "settings", "tracker"])
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    jobs = [(name, k, sc, args.source, str(args.out))
            for k, sc in enumerate(scenes(args.scenes, args.seed)) for name in RUNS]
    with ProcessPoolExecutor(args.workers) as pool:
        rows = list(pool.map(one, jobs))
    with (args.out / "confusion.csv").open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    labels = ["aligned", "not aligned", "unverified"]
    for key, what in (("truth", "the truth's verdict (aligned for hold_s at some time)"),
                      ("truth_end", "the truth at the run's end")):
        counts = Counter((r[key], r["label"]) for r in rows)
        print(f"{len(rows)} runs, judge: {args.source}; rows: {what}; columns: the judge")
        print(f"{'':>14}" + "".join(f"{lab:>14}" for lab in labels))
        for truth in ("aligned", "not aligned"):
            print(f"{truth:>14}" + "".join(f"{counts[(truth, lab)]:>14}" for lab in labels))
    bad = [r for r in rows if r["label"] == "aligned"
           and "not aligned" in (r["truth"], r["truth_end"])]
    for r in bad:
        print(f"FALSE ALIGNED: {r['run']} scene {r['scene']} ({r['set']}): {r['path']}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
