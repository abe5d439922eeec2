"""``ffexp sweep``: one protocol over a grid and/or a Latin-hypercube sample, with seeds.

:func:`prepare` reads and validates everything (keys, values, ranges, every
point against the protocol and scene models) before anything runs;
:func:`execute` runs the jobs through a :class:`~ffexp.sweeps.engine.Runner`
and writes the table, the figures and ``sweep.json``.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ffexp.errors import ConfigError
from ffexp.sweeps.engine import Runner
from ffexp.sweeps.keys import Key, Value, parse_assignment, parse_range
from ffexp.sweeps.plan import Point, Target, check_keys, grid, latin_hypercube, seeds_of
from ffexp.sweeps.rigs import StudyRig
from ffexp.sweeps.worker import INPUTS_DIR, Job, recording_kind


@dataclass
class Prepared:
    target: Target
    keys: list[Key]
    points: list[Point]
    seeds: list[int]
    command: list[str] = field(default_factory=list)

    def jobs(self, out_dir: Path) -> list[Job]:
        """The jobs into sweep directory ``out_dir`` (the inputs snapshot is written)."""
        out_dir = out_dir.resolve()
        inputs = self.target.snapshot(out_dir / INPUTS_DIR)
        return [self.target.job(self.keys, p, s, out_dir, inputs)
                for p in self.points for s in self.seeds]


def prepare(
    protocol: Path, *, vary: Sequence[str] = (), ranges: Sequence[str] = (),
    sample: int | None = None, sample_seed: int = 0, seeds: int = 1,
    fixed: Sequence[str] = (), rig: StudyRig | None = None,
) -> Prepared:
    """Everything a sweep runs, validated (one-line ConfigError, exit 2, on bad input);
    ``rig``: the rig of every run (``None``: the built-in rig)."""
    if not protocol.is_file():
        raise ConfigError(str(protocol), "", "file not found")
    target = Target(protocol, tuple(fixed), rig=rig)
    axes: list[tuple[Key, list[Value]]] = [parse_assignment(v, "--vary") for v in vary]
    spans: list[tuple[Key, float, float]] = []
    for text in ranges:
        key, lo, hi = parse_range(text, "--range")
        if key is None:
            raise ConfigError("--range", text, "expected KEY=LO:HI")
        spans.append((key, lo, hi))
    if spans and sample is None:
        raise ConfigError("--range", ranges[0], "a range needs --sample N")
    if sample is not None and not spans:
        raise ConfigError("--sample", str(sample), "needs at least one --range KEY=LO:HI")
    keys = [k for k, _ in axes] + [k for k, _, _ in spans]
    seen: set[str] = set()
    for k in keys:
        if k.text in seen:
            raise ConfigError("--vary", k.text, "key given twice")
        seen.add(k.text)
    points = grid(axes)
    if sample is not None:
        sampled = latin_hypercube(spans, sample, sample_seed)
        points = [{**p, **q} for p in points for q in sampled]
    seed_list = seeds_of(target, seeds)
    try:
        for p in points:
            target.check(keys, p, "--vary" if axes else "--range")
    except ConfigError:  # a key the protocol has not: its option's, not a sampled value's
        options = {k.text: "--vary" for k, _ in axes} | {k.text: "--range" for k, _, _ in spans}
        check_keys(target, keys, options)
        raise
    return Prepared(target, keys, points, seed_list, command=list(sys.argv))


def execute(prep: Prepared, runner: Runner, figures: bool = True) -> dict[str, Any]:
    """Run the sweep; write ``results.csv``/``.parquet``, figures and ``sweep.json``
    (``rig``: the runs' rig; ``recording``: how the runs were asked to record,
    :attr:`Runner.lean`).

    Returns a summary: rows, table paths, figure paths, counts.
    """
    from ffexp.sweeps import plots, table

    jobs = prep.jobs(runner.out_dir)
    (runner.out_dir / "sweep.json").write_text(json.dumps({
        "kind": "sweep", "protocol": str(prep.target.protocol_path),
        "protocol_id": prep.target.ident, "rig": prep.target.rig_name,
        "fixed": list(prep.target.fixed),
        "keys": [k.text for k in prep.keys], "points": len(prep.points),
        "seeds": prep.seeds, "runs": [j.run_id for j in jobs], "command": prep.command,
        "recording": recording_kind(runner.lean),
    }, indent=2) + "\n")
    rows = runner.run_batch(jobs)
    df = table.frame(rows)
    paths = table.write(df, runner.out_dir)
    figs: list[Path] = []
    if figures:
        title = f"{prep.target.label}: {len(rows)} runs, {len(prep.seeds)} seed(s) per point"
        figs = plots.sweep_figures(df, [k.text for k in prep.keys], runner.out_dir / "figures",
                                   title, nominal=plots.nominal_values(prep.target, prep.keys))
    return {"rows": rows, "tables": paths, "figures": figs}
