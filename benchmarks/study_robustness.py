"""Robustness study: the paper's four runs over a neighbourhood of the nominal scene.

    python benchmarks/study_robustness.py [--axes lateral,yaw] [--workers 2] [--csv FILE]
                                          [--set scene.key=value ...]

Runs Method I case I and case II at 0.8 N, Method II at 0.8 N and 1.5 N and
Method III (impedance) in every scene of a grid around the nominal one
(``data/scenes/paper.toml``): target lateral offset +-4 mm and yaw +-3 deg
(how far an operator places the target by hand), bed friction 0.002 to
0.009, joint friction x0.7 to x1.4, approach speed x0.75 to x1.25, noise
seeds. ``--axes`` picks which of them vary (the others stay nominal). It
prints, per run, a map of the outcome over the first two varied axes (A:
aligned, .: not, !: aborted) so a flip between neighbouring grid points is
visible, the number of such flips, and claim by claim the fraction of scenes
where the paper's statement holds. A study, not a benchmark of speed: the
full grid takes long; run it by hand.
"""

from __future__ import annotations

import argparse
import csv
import itertools
import json
import os
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
from drivers.sim.scene import load_scene  # noqa: E402  (the repository, not an install)

NOMINAL = load_scene(ROOT / "data/scenes/paper.toml")
NOMINAL_SPEED_MPS = 0.02  # the paper protocols' approach speed

#: The axes of the neighbourhood: name -> (override template, values).
AXES: dict[str, tuple[str, list[float]]] = {
    "lateral": ("scene:target.lateral={}", [NOMINAL.target.lateral + d for d in
                                             (-0.004, -0.002, 0.0, 0.002, 0.004)]),
    "yaw": ("scene:target.yaw_deg={}",
            [NOMINAL.target.yaw_deg + d for d in (-3.0, -1.5, 0.0, 1.5, 3.0)]),
    "mu": ("scene:target.mu={}", [0.002, 0.0045, 0.007, 0.009]),
    "joint_friction": ("scene:arm.friction_scale={}",
                       [NOMINAL.arm.friction_scale * k for k in (0.7, 1.0, 1.4)]),
    "speed": ("approach.speed_mps={}", [NOMINAL_SPEED_MPS * k for k in (0.75, 1.0, 1.25)]),
    "seed": ("seed={}", [1, 2, 3]),
}

#: The paper's runs: name -> (protocol, extra overrides).
RUNS: dict[str, tuple[str, list[str]]] = {
    "I-1 0.8N": ("protocols/method1_case1.toml", []),
    "I-2 0.8N": ("protocols/method1_case2.toml", []),
    "II 0.8N": ("protocols/method2.toml", ["align.f_ref=[0,0,0.8,0,0,0]"]),
    "II 1.5N": ("protocols/method2.toml", []),
    "III": ("protocols/method3_impedance.toml", []),
}
#: Method III "keeps breaking": at least this many contact breaks.
III_BREAKS = 3


def _overrides(scene_point: dict[str, float], extra: list[str]) -> list[str]:
    scene_set, out = [], list(extra)
    for axis, value in scene_point.items():
        template = AXES[axis][0]
        if template.startswith("scene:"):
            scene_set.append(template.removeprefix("scene:").format(value))
        else:
            out.append(template.format(value))
    if scene_set:
        out.append("scene.set=" + json.dumps(scene_set))
    return out


def run_one(job: tuple[str, dict[str, float], list[str]]) -> dict[str, object]:
    run, point, extra_set = job
    from ffexp.analysis import metrics
    from ffexp.experiment import run_file
    from ffexp.recording.reader import load

    protocol, extra = RUNS[run]
    t0 = time.perf_counter()
    row: dict[str, object] = {"run": run, **point}
    with tempfile.TemporaryDirectory() as tmp:
        try:
            result = run_file(ROOT / protocol, _overrides(point, extra + extra_set),
                              out_dir=Path(tmp))
            m = metrics(load(result.path))
            row.update(aligned=m.aligned, breaks=m.contact_breaks, aborted=m.aborted or "",
                       contact_s=m.first_contact_s, aligned_s=m.alignment_time_s,
                       mean_fz_align_n=m.mean_fz_align_n, target_moved_m=m.target_displacement_m)
        except Exception as exc:  # a failing run is a row with its error
            row.update(aligned=False, breaks=-1, aborted=f"error: {exc}")
    row["wall_s"] = time.perf_counter() - t0
    return row


def claims(rows: list[dict[str, object]], points: list[dict[str, float]]) -> dict[str, float]:
    """Fraction of scenes where each claim of the paper holds."""
    def at(point: dict[str, float], run: str) -> dict[str, object]:
        return next(r for r in rows if r["run"] == run and all(r[k] == v for k, v in point.items()))

    holds: dict[str, list[bool]] = {k: [] for k in (
        "I-1 aligns at 0.8 N", "I-2 aligns at 0.8 N", "II does not align at 0.8 N",
        "II aligns at 1.5 N", f"III breaks contact >= {III_BREAKS} times",
        "force control: I-1 aligns at 0.8 N, II needs 1.5 N",
        "the ordering (I-1, II at 0.8 and 1.5 N, III)")}
    for p in points:
        i1, i2, ii08, ii15, iii = (at(p, r) for r in RUNS)
        c = [bool(i1["aligned"]), bool(i2["aligned"]), not ii08["aligned"], bool(ii15["aligned"]),
             int(iii["breaks"]) >= III_BREAKS]  # type: ignore[call-overload]
        force = c[0] and c[2] and c[3]
        for key, ok in zip(holds, [*c, force, force and c[4]], strict=True):
            holds[key].append(ok)
    return {k: sum(v) / len(v) for k, v in holds.items()}


def outcome_maps(rows: list[dict[str, object]], axes: list[str]) -> tuple[str, int]:
    """Per run, the outcome over the first two axes (others nominal or first), and the flips."""
    if len(axes) < 2:
        return "", 0
    a, b = axes[:2]
    lines, flips = [], 0
    for run in RUNS:
        sub = {(r[a], r[b]): r for r in rows if r["run"] == run}
        va, vb = AXES[a][1], AXES[b][1]
        lines.append(f"{run}: rows {a}, columns {b}")
        for x in va:
            cells = []
            for y in vb:
                r = sub.get((x, y))
                cells.append("?" if r is None else "!" if r["aborted"] else
                             "A" if r["aligned"] else ".")
            lines.append(f"  {x:9.4g} " + " ".join(cells))
        grid = [[bool(sub[(x, y)]["aligned"]) if (x, y) in sub else None for y in vb] for x in va]
        for i, j in itertools.product(range(len(va)), range(len(vb))):
            for di, dj in ((1, 0), (0, 1)):
                if i + di < len(va) and j + dj < len(vb):
                    u, v = grid[i][j], grid[i + di][j + dj]
                    flips += u is not None and v is not None and u != v
    return "\n".join(lines), flips


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--axes", default="lateral,yaw",
                    help=f"comma-separated, from {', '.join(AXES)}")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--csv", type=Path, default=None, help="write every run's row here")
    ap.add_argument("--set", action="append", default=[], dest="extra",
                    help="an extra protocol override for every run (e.g. align.kp=...)")
    args = ap.parse_args(argv)
    axes = [a for a in args.axes.split(",") if a]
    unknown = [a for a in axes if a not in AXES]
    if unknown:
        print(f"error: --axes: unknown axis {unknown[0]!r} (known: {', '.join(AXES)})",
              file=sys.stderr)
        return 2
    points = [dict(zip(axes, vals, strict=True))
              for vals in itertools.product(*(AXES[a][1] for a in axes))]
    jobs = [(run, p, list(args.extra)) for p in points for run in RUNS]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.workers) as ex:
        rows = list(ex.map(run_one, jobs))
    wall = time.perf_counter() - t0
    if args.csv is not None:
        keys = sorted({k for r in rows for k in r})
        with args.csv.open("w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=keys)
            w.writeheader()
            w.writerows(rows)
    maps, flips = outcome_maps(rows, axes)
    print(f"{len(points)} scenes x {len(RUNS)} runs in {wall:.0f} s on {args.workers} workers")
    if maps:
        print(maps)
        print(f"flips between neighbouring grid points (all runs): {flips}")
    for claim, frac in claims(rows, points).items():
        print(f"  {frac:6.0%}  {claim}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
