"""``ffexp reproduce``: the paper's runs over scenes of uncertain rig parameters, claim
by claim (protocols/reproduce.toml, protocols/robustness.toml).

The config names the paper runs by role (protocol file and overrides, see
:mod:`ffexp.sweeps.claims`), the uncertain scene keys as ranges (a Latin
hypercube of ``sample`` scenes) or as a ``[grid]`` (the full product), the
noise seeds of every scene, and the limit searches done at the nominal scene.
Scenes and limit searches run at once through one Runner.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from pydantic import Field, ValidationError, field_validator, model_validator

from drivers.config import StrictModel
from ffexp.errors import ConfigError
from ffexp.filekind import load_as
from ffexp.sweeps import claims
from ffexp.sweeps.engine import Runner
from ffexp.sweeps.keys import Key, Value, current_value, parse_key
from ffexp.sweeps.plan import Point, Target, grid, latin_hypercube
from ffexp.sweeps.rigs import StudyRig
from ffexp.sweeps.searches import LimitSearch
from ffexp.sweeps.worker import recording_kind


class RunRole(StrictModel):
    protocol: str
    set: list[str] = Field(default_factory=list)


class LimitSpec(StrictModel):
    name: str
    run: str = Field(description="The role whose protocol is searched.")
    key: str
    range: tuple[float, float]
    resolution: float = Field(gt=0)
    paper: tuple[float, float] | None = Field(
        None, description="The paper's lower and upper limit (a gain-limit claim).")
    coarse: int = Field(5, ge=2)
    max_breaks: int | None = Field(
        None, ge=0, description="A run aligns only with at most this many contact breaks.")


class Relative(StrictModel):
    """Values relative to the nominal one (the resolved scene or protocol of the first
    run): ``offset`` adds, ``scale`` multiplies; exactly one of them."""

    offset: list[float] | None = None
    scale: list[float] | None = None

    @model_validator(mode="after")
    def _one(self) -> Relative:
        if (self.offset is None) == (self.scale is None):
            raise ValueError("give exactly one of offset = [...] or scale = [...]")
        if not (self.offset or self.scale):
            raise ValueError("no values")
        return self

    def values(self, nominal: float) -> list[float]:
        if self.offset is not None:
            return [float(f"{nominal + d:.10g}") for d in self.offset]
        assert self.scale is not None
        return [float(f"{nominal * k:.10g}") for k in self.scale]


class ClaimSettings(StrictModel):
    iii_min_breaks: int = Field(3, ge=1)
    i1_max_breaks: int = Field(1, ge=0)
    fz_tolerance: float = Field(0.15, gt=0)
    limit_factor: float = Field(2.0, gt=1)
    f_ref_low_n: float = Field(0.8, description="The f_ref at which I aligns and II does not.")
    f_ref_high_n: float = Field(1.5, description="The f_ref at which II aligns.")


class ReproduceConfig(StrictModel):
    name: str = "reproduce"
    description: str = ""
    seeds: list[int] = Field(default_factory=lambda: [1], min_length=1)
    sample: int | None = Field(None, ge=1)
    sample_seed: int = 0
    include_nominal: bool = True
    ranges: dict[str, tuple[float, float] | Relative] = Field(default_factory=dict)
    grid: dict[str, list[float] | Relative] = Field(default_factory=dict)

    @field_validator("ranges", "grid", mode="before")
    @classmethod
    def _relative(cls, data: Any) -> Any:
        """``{ offset = [...] }`` / ``{ scale = [...] }`` tables as :class:`Relative`, with
        their own error (not pydantic's about the list form)."""
        if not isinstance(data, dict):
            return data
        out = {}
        for key, value in data.items():
            if isinstance(value, dict):
                try:
                    value = Relative.model_validate(value)
                except ValidationError as exc:
                    err = exc.errors()[0]
                    msg = str(err.get("ctx", {}).get("error", err["msg"]))
                    raise ValueError(f"{key}: {msg}") from None
            out[key] = value
        return out
    runs: dict[str, RunRole]
    claims: ClaimSettings = ClaimSettings()
    limits: list[LimitSpec] = Field(default_factory=list)
    min_f_ref: tuple[str, str] | None = Field(
        None, description="Names of the two f_ref limit searches: with and without inertia "
        "reduction (the minimum-f_ref claim).")
    recording: Literal["lean", "full"] = Field(
        "lean", description="The runs' recordings: lean (the topics the metrics read; the "
        "study reads only its rows) or full (every topic, to open in report, figures, "
        "replay or Foxglove). ffexp reproduce --full/--lean overrides it.")

    @model_validator(mode="after")
    def _check(self) -> ReproduceConfig:
        missing = [r for r in claims.ROLES if r not in self.runs]
        if missing:
            raise ValueError(f"runs: missing role(s) {', '.join(missing)}")
        if self.ranges and self.sample is None:
            raise ValueError("ranges need sample = N")
        for lo_hi in self.ranges.values():
            if isinstance(lo_hi, Relative):
                if len(lo_hi.values(1.0)) != 2:
                    raise ValueError("a relative range needs two values: [low, high]")
            elif not lo_hi[0] < lo_hi[1]:
                raise ValueError(f"empty range {list(lo_hi)}")
        for values in self.grid.values():
            if not isinstance(values, Relative) and not values:
                raise ValueError("a grid key without values")
        names = [spec.name for spec in self.limits]
        for spec in self.limits:
            if spec.run not in self.runs:
                raise ValueError(f"limits {spec.name}: unknown run {spec.run!r}")
        if self.min_f_ref is not None and any(n not in names for n in self.min_f_ref):
            raise ValueError("min_f_ref: names limit searches that are not in [[limits]]")
        return self


@dataclass
class Study:
    """A loaded config with its targets and scenes, validated."""

    path: Path
    config: ReproduceConfig
    targets: dict[str, Target]
    keys: list[Key]
    scenes: list[Point]
    searches: list[LimitSearch]
    axes: list[tuple[Key, list[Any]]] = field(default_factory=list)
    """The grid's axes when the scenes are a pure grid (neighbours are defined)."""


def load(path: Path, fixed: Sequence[str] = (), rig: StudyRig | None = None) -> Study:
    """Read and validate the config, every protocol and every scene (before any run), each
    paper run on ``rig`` (``None``: the built-in rig)."""
    cfg = load_as(ReproduceConfig, path, (), "study")
    targets = {}
    for role, run in cfg.runs.items():
        proto = path.parent / run.protocol
        if not proto.is_file():
            raise ConfigError(str(path), f"runs.{role}.protocol", f"{proto}: file not found")
        targets[role] = Target(proto, (*run.set, *fixed), label=role, rig=rig)
    first = next(iter(targets.values()))
    axes = []
    for text, vals in cfg.grid.items():
        key = parse_key(text, str(path))
        axes.append((key, _absolute(path, first, key, vals, "grid")))
    spans = []
    for text, lo_hi in cfg.ranges.items():
        key = parse_key(text, str(path))
        lo, hi = _absolute(path, first, key, lo_hi, "ranges")
        if not lo < hi:
            raise ConfigError(str(path), f"ranges.{text}", f"empty range [{lo:g}, {hi:g}]")
        spans.append((key, lo, hi))
    keys = [k for k, _ in axes] + [k for k, _, _ in spans]
    scenes = grid(axes) if axes else [{}]
    if spans and cfg.sample is not None:
        sampled = latin_hypercube(spans, cfg.sample, cfg.sample_seed)
        scenes = [{**p, **q} for p in scenes for q in sampled]
    if cfg.include_nominal and keys:
        scenes = [{}, *scenes]
    for scene in scenes:
        for target in targets.values():
            target.check([k for k in keys if k.text in scene], scene, str(path))
    searches = []
    for spec in cfg.limits:
        key = parse_key(spec.key, f"{path}: limits.{spec.name}.key")
        search = LimitSearch(targets[spec.run], [key], [spec.range], [cfg.seeds[0]],
                             [spec.resolution], spec.coarse, name=spec.name,
                             max_breaks=spec.max_breaks)
        search.check()
        searches.append(search)
    return Study(path, cfg, targets, keys, scenes, searches, axes if not spans else [])


def _absolute(path: Path, target: Target, key: Key, values: Any, table: str) -> list[Any]:
    """Grid or range values as numbers: relative ones from the key's nominal value."""
    if not isinstance(values, Relative):
        return list(values)
    try:
        nominal = current_value(key, target.protocol.model_dump(mode="json"),
                                target.scene.model_dump(mode="json"))
    except ConfigError as exc:
        raise ConfigError(str(path), f"{table}.{key.text}", exc.message) from None
    if not isinstance(nominal, int | float) or isinstance(nominal, bool):
        raise ConfigError(str(path), f"{table}.{key.text}",
                          f"relative values need a number; the nominal value is {nominal!r}")
    return values.values(float(nominal))


def search_budget(search: LimitSearch) -> int:
    """The runs a limit search is expected to make: its coarse grid along every segment
    and, per segment, one bracket bisected down to the resolution; every point with
    every seed. (A segment with more changes of outcome bisects more brackets, one
    without any fewer: an estimate, for the time left.)"""
    segments = search.segments()
    step = 1.0 / (search.coarse - 1)
    points = search.coarse + (search.coarse - 1) * (len(segments) - 1)  # rays share t = 0
    for seg in segments:
        t_res = seg.t_resolution(search.resolution)
        points += math.ceil(math.log2(step / t_res) - 1e-9) if step > t_res else 0
    return points * len(search.seeds)


def planned_runs(study: Study) -> int:
    """Every scene's paper runs and every limit search's expected runs (before any run:
    the searches add theirs round by round)."""
    scenes = len(study.scenes) * len(study.targets) * len(study.config.seeds)
    return scenes + sum(search_budget(s) for s in study.searches)


def run(study: Study, runner: Runner) -> dict[str, Any]:
    """Every scene's paper runs and every limit search, at once; the claims."""
    cfg = study.config
    runner.plan(planned_runs(study))
    inputs = {role: t.snapshot(runner.inputs) for role, t in study.targets.items()}
    jobs = []
    for scene in study.scenes:
        keys = [k for k in study.keys if k.text in scene]
        for role, target in study.targets.items():
            for seed in cfg.seeds:
                jobs.append(target.job(keys, scene, seed, runner.out_dir, inputs[role]))
    pool = ThreadPoolExecutor(max_workers=1 + len(study.searches))
    try:
        scene_rows = pool.submit(runner.run_batch, jobs)
        searches = [pool.submit(s.run, runner) for s in study.searches]
        rows = scene_rows.result()
        for fut in searches:
            fut.result()
        runner.plan(0)  # all ran: the runs made are the plan (the estimate is done with)
    finally:  # on an interrupt, do not wait here for the runs (the session ends them)
        pool.shutdown(wait=False, cancel_futures=True)
    return {**evaluate(study, rows), "recording": recording_kind(runner.lean)}


def evaluate(study: Study, rows: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Per scene and seed: each run's outcome and each claim; the summary; the limits."""
    cfg = study.config
    settings = claims.Settings(cfg.claims.iii_min_breaks, cfg.claims.fz_tolerance,
                               cfg.claims.limit_factor, cfg.claims.i1_max_breaks)
    per_scene: list[dict[str, Any]] = []
    n_roles, n_seeds = len(study.targets), len(cfg.seeds)
    roles = list(study.targets)
    for i, scene in enumerate(study.scenes):
        block = rows[i * n_roles * n_seeds:(i + 1) * n_roles * n_seeds]
        for j, seed in enumerate(cfg.seeds):
            runs = {role: block[r * n_seeds + j] for r, role in enumerate(roles)}
            entry: dict[str, Any] = {"scene": i, **{k.text: scene.get(k.text) for k in
                                                    study.keys}, "seed": seed}
            for role, row in runs.items():
                entry[f"{role} aligned"] = None if row.get("error") else bool(row.get("aligned"))
                entry[f"{role} breaks"] = row.get("contact_breaks")
                entry[f"{role} breaks ALIGN"] = row.get("breaks_align")
                entry[f"{role} mean f_z"] = row.get("mean_fz_align_n")
            for c in claims.SCENE_CLAIMS:
                entry[c.name] = c.judge(runs, settings)
            per_scene.append(entry)
    summary = claims.summarize(per_scene, claims.SCENE_CLAIMS)
    at_nominal = [e for e in per_scene if e["scene"] == 0] if (
        cfg.include_nominal and study.keys) else []
    for item in summary:  # the claim at the nominal scene (over its seeds: most of them)
        judged = [bool(e[item["claim"]]) for e in at_nominal if e[item["claim"]] is not None]
        item["nominal"] = sum(judged) > len(judged) / 2 if judged else None
    for item in _limit_claims(study, settings):  # searched at the nominal scene
        summary.append({**item, "nominal": bool(item["holds"])})
    limit_rows = [row for s in study.searches if s.result is not None
                  for row in s.limits_rows()]
    return {"scenes": per_scene, "summary": summary, "limits": limit_rows,
            "flips": flips(study, per_scene), "regions": regions(study, per_scene),
            "rows": list(rows) + [r for s in study.searches for r in s.rows]}


#: The claims whose region (fraction and centre) the study reports.
REGION_CLAIMS = ("ordering", "all")


def regions(study: Study, per_scene: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Where the paper's comparison and every claim hold: each one's fraction of the
    scenes and the centre of the scenes where it holds (:func:`claims.region`)."""
    if not study.keys or not study.targets:
        return []
    from ffexp.sweeps import plots

    nominal = plots.nominal_values(next(iter(study.targets.values())), study.keys)
    names = [k.text for k in study.keys]
    return [claims.region(per_scene, c, names, nominal) for c in REGION_CLAIMS]


def flips(study: Study, per_scene: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Per outcome (each run's aligned flag, each claim): flips between neighbouring
    grid points (the outcome over seeds: more than half), of how many pairs. Empty
    unless the scenes are a grid."""
    if not study.axes:
        return []
    axes = [(k.text, values) for k, values in study.axes]
    by_scene: dict[int, list[Mapping[str, Any]]] = {}
    for entry in per_scene:
        by_scene.setdefault(int(entry["scene"]), []).append(entry)
    outcomes = [f"{role} aligned" for role in study.targets] + [
        c.name for c in claims.SCENE_CLAIMS]
    out = []
    for name in outcomes:
        verdicts: list[bool | None] = []
        for i in range(len(study.scenes)):
            judged = [bool(e[name]) for e in by_scene.get(i, []) if e[name] is not None]
            verdicts.append(sum(judged) > len(judged) / 2 if judged else None)
        n_flips, pairs = claims.neighbour_flips(study.scenes, verdicts, axes)
        out.append({"outcome": name, "flips": n_flips, "pairs": pairs})
    return out


def _limit_claims(study: Study, settings: claims.Settings) -> list[dict[str, Any]]:
    out = []
    by_name = {s.name: s for s in study.searches}
    specs = {spec.name: spec for spec in study.config.limits}
    for name, search in by_name.items():
        spec = specs[name]
        if spec.paper is None or search.result is None:
            continue
        found = search.limits_rows()
        lo, hi, n = claims.lower_upper(found, spec.key)
        ok = claims.gain_limits(found, spec.key, spec.paper, settings)
        span = f"{spec.range[0]:g}..{spec.range[1]:g}"
        if n == 0:
            everywhere = all(f > 0.5 for f in search.result.evaluated.values())
            seen = f"aligns {'everywhere' if everywhere else 'nowhere'} in {span}"
        else:
            seen = (f"lower {_g(lo)}, upper {_g(hi)} ({n} change(s) in {span}, resolution "
                    f"{spec.resolution:g})")
        out.append(_one(f"{name} limits", f"aligns for {spec.key} between {spec.paper[0]:g} "
                        f"and {spec.paper[1]:g}", ok, f"ours: {seen}"))
    if study.config.min_f_ref is not None:
        mins: list[float | None] = []
        for name in study.config.min_f_ref:
            s, spec = by_name[name], specs[name]
            if s.result is None:
                mins.append(None)
                continue
            low = s.result.evaluated.get((float(f"{spec.range[0]:.10g}"),), 0.0)
            mins.append(claims.minimum_aligning(s.limits_rows(), spec.key, low > 0.5,
                                                spec.range[0]))
        c = study.config.claims
        ok = claims.minimum_f_ref(mins[0], mins[1], c.f_ref_low_n, c.f_ref_high_n)
        out.append(_one("minimum f_ref", f"with inertia reduction aligns at {c.f_ref_low_n:g} "
                        f"N; without it needs more, up to {c.f_ref_high_n:g} N", ok,
                        f"ours: {_g(mins[0])} N with, {_g(mins[1])} N without"))
    return out


def _g(x: float | None) -> str:
    return "none" if x is None else f"{x:.3g}"


def _one(name: str, paper: str, ok: bool, note: str) -> dict[str, Any]:
    return {"claim": name, "paper": paper, "holds": int(ok), "scenes": 1,
            "fraction": float(ok), "not judged": 0, "note": note}


def write(study: Study, result: Mapping[str, Any], out_dir: Path) -> list[Path]:
    """``scenes.csv`` (per scene: runs and claims), ``claims.csv`` (the summary),
    ``limits.csv``, ``results.csv``/``.parquet`` (every run), ``reproduce.json``, the
    figure."""
    from ffexp.sweeps import plots, table

    paths = table.write(table.frame(result["rows"]), out_dir)
    for name, rows in (("scenes.csv", result["scenes"]), ("claims.csv", result["summary"]),
                       ("limits.csv", result["limits"]), ("flips.csv", result["flips"])):
        tmp = out_dir / f".{name}.tmp"
        table.frame(rows).drop(columns=list(table.TAIL), errors="ignore").to_csv(
            tmp, index=False)
        tmp.replace(out_dir / name)
        paths.append(out_dir / name)
    (out_dir / "reproduce.json").write_text(json.dumps({
        "kind": "reproduce", "config": str(study.path),
        "rig": next(iter(study.targets.values())).rig_name, "config_json":
        study.config.model_dump(mode="json"), "summary": result["summary"],
        "limits": result["limits"], "flips": result["flips"],
        "regions": result.get("regions", []), "recording": result.get("recording", "full"),
    }, indent=2, default=str) + "\n")
    paths.append(out_dir / "reproduce.json")
    paths.append(plots.claims_figure(result["summary"], f"{study.config.name}: "
                                     f"{len(study.scenes)} scenes x {len(study.config.seeds)} "
                                     "seed(s)", out_dir / "figures" / "claims.png"))
    outcomes = [f"{role} aligned" for role in study.targets] + [
        c.name for c in claims.SCENE_CLAIMS]
    mapped = plots.scene_map(table.frame(result["scenes"]), [k.text for k in study.keys],
                             outcomes, f"{study.config.name}: outcomes over the scenes",
                             out_dir / "figures" / "scenes.png",
                             nominal=plots.nominal_values(next(iter(study.targets.values())),
                                                          study.keys))
    if mapped is not None:
        paths.append(mapped)
    return paths


__all__ = ["ReproduceConfig", "Study", "Value", "evaluate", "load", "run", "write"]
