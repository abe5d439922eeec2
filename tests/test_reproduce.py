"""``ffexp reproduce``: the claims on synthetic rows, the config's validation, and one
tiny study end to end (short runs; its outcomes are not asserted: the simulator is
being changed, the mechanism is: scenes x roles rows, claims per scene, files)."""

from __future__ import annotations

import json
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import pandas as pd
import pytest
from typer.testing import CliRunner

from drivers.description.scene import IMPULSE_TEST_MU_BOUND, load_scene
from ffexp.cli import app
from ffexp.sweeps import claims, engine
from ffexp.sweeps import reproduce as rep

ROOT = Path(__file__).resolve().parents[1]
S = claims.Settings(iii_min_breaks=3, fz_tolerance=0.15, limit_factor=2.0, i1_max_breaks=1)
cli = CliRunner()


def row(aligned: bool, breaks: int = 0, fz: float | None = None, ref: float | None = None,
        error: str | None = None, breaks_align: int | None = None) -> dict[str, Any]:
    return {"aligned": aligned, "contact_breaks": breaks, "mean_fz_align_n": fz,
            "f_ref_n": ref, "error": error,
            "breaks_align": breaks if breaks_align is None else breaks_align}


def paper_like() -> dict[str, dict[str, Any]]:
    return {"I-1": row(True, 1, 0.78, 0.8), "I-2": row(True, 1, 0.75, 0.8),
            "II-0.8": row(False, 0, 0.8, 0.8), "II-1.5": row(True, 0, 1.45, 1.5),
            "III": row(False, 4)}


def test_claims_hold_on_the_paper_outcome() -> None:
    runs = paper_like()
    for c in claims.SCENE_CLAIMS:
        assert c.judge(runs, S) is True, c.name


ORDER = {"ordering", "all"}


@pytest.mark.parametrize(("role", "change", "broken"), [
    ("I-1", row(False), {"I-1 aligns", "f_z tracking"} | ORDER),
    ("I-1", row(True, 2, 0.78, 0.8), {"I-1 aligns"} | ORDER),  # two breaks in ALIGN
    ("II-0.8", row(True, 0, 0.8, 0.8), {"II at 0.8 N fails"} | ORDER),
    ("II-1.5", row(False, 0, 1.45, 1.5), {"II at 1.5 N aligns"} | ORDER),
    ("III", row(True, 0), {"III breaks contact"} | ORDER),
    ("III", row(False, 2), {"III breaks contact"} | ORDER),
    ("I-2", row(False), {"I-2 aligns at 0.8 N", "f_z tracking", "all"}),
    ("II-1.5", row(True, 0, 1.2, 1.5), {"f_z tracking", "all"}),  # 20 % low
])
def test_each_claim_fails_where_it_should(role: str, change: dict[str, Any], broken: set[str]
                                          ) -> None:
    runs = {**paper_like(), role: change}
    failed = {c.name for c in claims.SCENE_CLAIMS if c.judge(runs, S) is False}
    if role in ("I-1", "I-2") and change["mean_fz_align_n"] is None:
        broken = broken - {"f_z tracking"}  # a run without ALIGN is not judged on f_z
    assert failed == broken


def test_iii_seated_for_a_moment_and_breaking_on_is_still_paper_like() -> None:
    """III counts breaks after the first contact over its whole run, a seat or not."""
    runs = {**paper_like(), "III": row(True, 5, breaks_align=1)}
    assert claims.ordering(runs, S) is True and claims.iii_breaks(runs, S) is True


def test_i1_counts_only_breaks_in_align() -> None:
    runs = {**paper_like(), "I-1": row(True, 3, 0.78, 0.8, breaks_align=1)}
    assert claims.i1_aligns(runs, S) is True


def test_a_failed_run_is_not_judged() -> None:
    runs = {**paper_like(), "II-0.8": row(False, error="SimulationError: diverged")}
    assert claims.ordering(runs, S) is None
    assert claims.i2_aligns(runs, S) is True
    summary = claims.summarize([{c.name: c.judge(runs, S) for c in claims.SCENE_CLAIMS},
                                {c.name: c.judge(paper_like(), S) for c in
                                 claims.SCENE_CLAIMS}], claims.SCENE_CLAIMS)
    first = next(r for r in summary if r["claim"] == "ordering")
    assert (first["holds"], first["scenes"], first["not judged"], first["fraction"]) == \
        (1, 1, 1, 1.0)


def test_gain_limits_and_minimum_f_ref() -> None:
    found = [{"kind": "lower", "k": 0.45}, {"kind": "upper", "k": 2.6}]
    assert claims.gain_limits(found, "k", (0.5, 2.0), S)
    assert not claims.gain_limits(found, "k", (0.5, 1.0), S)  # 2.6 > 2 x 1.0
    assert not claims.gain_limits(found[:1], "k", (0.5, 2.0), S)  # no upper limit
    assert not claims.gain_limits([*found, {"kind": "lower", "k": 3.0}], "k", (0.5, 2.0), S)
    assert claims.minimum_aligning([], "f", True, 0.2) == 0.2
    assert claims.minimum_aligning([{"kind": "lower", "f": 1.1}], "f", False, 0.2) == 1.1
    assert claims.minimum_aligning([], "f", False, 0.2) is None
    assert claims.minimum_f_ref(0.5, 1.1)
    assert not claims.minimum_f_ref(0.5, 0.7)  # II aligns at 0.8 N too
    assert not claims.minimum_f_ref(0.9, 1.1)  # I needs more than 0.8 N
    assert not claims.minimum_f_ref(0.5, None)


def test_neighbour_flips_count_changes_between_grid_neighbours() -> None:
    axes = [("a", [0, 1, 2]), ("b", [10, 20, 30])]
    scenes = [{"a": a, "b": b} for a in (0, 1, 2) for b in (10, 20, 30)]
    step = [s["a"] >= 1 for s in scenes]  # a boundary between a=0 and a=1
    assert claims.neighbour_flips(scenes, step, axes) == (3, 12)
    checker = [(s["a"] + s["b"] // 10) % 2 == 0 for s in scenes]
    assert claims.neighbour_flips(scenes, checker, axes) == (12, 12)
    some = [None if s == {"a": 1, "b": 20} else v for s, v in zip(scenes, step, strict=True)]
    assert claims.neighbour_flips(scenes, some, axes) == (2, 8)  # the centre has 4 pairs
    nominal = [{}, *scenes]  # a scene off the grid is ignored
    assert claims.neighbour_flips(nominal, [True, *step], axes) == (3, 12)


def test_a_claims_region_is_its_fraction_and_the_centre_of_its_scenes() -> None:
    # the nominal scene (no key values: its nominal ones) and four scenes of a box
    scenes = [{"a": None, "b": None, "all": True}, {"a": 0.0, "b": 10.0, "all": False},
              {"a": 1.0, "b": 30.0, "all": True}, {"a": 3.0, "b": 20.0, "all": True},
              {"a": 4.0, "b": 40.0, "all": None}]
    r = claims.region(scenes, "all", ["a", "b"], {"a": 2.0, "b": 20.0})
    assert (r["holds"], r["scenes"], r["fraction"]) == (3, 4, 0.75)  # one not judged
    assert r["centre"] == {"a": 2.0, "b": pytest.approx(70.0 / 3)}  # (2 + 1 + 3) / 3
    assert r["span"] == {"a": 0.5, "b": pytest.approx(1.0 / 3)}  # of 0..4 and 10..40
    none = claims.region(scenes[1:2], "all", ["a"], {"a": 2.0})
    assert (none["holds"], none["fraction"], none["centre"]) == (0, 0.0, {})


def _config(tmp_path: Path, body: str) -> Path:
    runs = "\n".join(
        f'"{role}" = {{ protocol = "{ROOT}/protocols/{p}", set = {sets} }}'
        for role, p, sets in (
            ("I-1", "method1_case1.toml", "[]"), ("I-2", "method1_case2.toml", "[]"),
            ("II-0.8", "method2.toml", '["align.f_ref=[0.0, 0.0, 0.8, 0.0, 0.0, 0.0]"]'),
            ("II-1.5", "method2.toml", "[]"), ("III", "method3_impedance.toml", "[]")))
    path = tmp_path / "study.toml"
    path.write_text(body + "\n[runs]\n" + runs + "\n")
    return path


@pytest.mark.parametrize(("body", "needle"), [
    ('name = "x"\nsample = 2\n[ranges]\n"scene.target.nope" = [0.0, 1.0]', "target.nope"),
    ('name = "x"\n[ranges]\n"scene.target.mu" = [0.0, 1.0]', "sample"),
    ('name = "x"\nsample = 2\n[ranges]\n"scene.target.mu" = [0.01, 0.001]', "empty range"),
    ('name = "x"\n[grid]\n"scene.target.mu" = ["a"]', "grid"),
    ('name = "x"\nmin_f_ref = ["a", "b"]', "min_f_ref"),
    ('name = "x"\ncolour = 1', "colour"),
    ('name = "x"\n[grid]\n"scene.target.mu" = { offset = [0.0], scale = [1.0] }', "exactly one"),
    ('name = "x"\n[grid]\n"scene.target.funnel.surface" = { scale = [1.0] }', "a number"),
    ('name = "x"\n[grid]\n"scene.target.nope" = { scale = [1.0] }', "target.nope"),
    ('name = "x"\nsample = 2\n[ranges]\n"scene.target.mu" = { scale = [2.0, 1.0] }',
     "empty range"),
])
def test_config_errors_one_line_exit_2(tmp_path: Path, body: str, needle: str) -> None:
    cfg = _config(tmp_path, body)
    res = cli.invoke(app, ["reproduce", "--config", str(cfg), "--out", str(tmp_path / "o")])
    assert res.exit_code == 2, res.output
    err = res.stderr.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and needle in err[0], err
    assert not (tmp_path / "o").exists()


def test_missing_role_is_an_error(tmp_path: Path) -> None:
    cfg = tmp_path / "study.toml"
    cfg.write_text(f'[runs]\n"I-1" = {{ protocol = "{ROOT}/protocols/method1_case1.toml" }}\n')
    res = cli.invoke(app, ["reproduce", "--config", str(cfg), "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and "missing role" in res.stderr


def test_shipped_configs_validate() -> None:
    for name in ("reproduce.toml", "robustness.toml"):
        study = rep.load(ROOT / "protocols" / name)
        assert set(study.targets) == set(claims.ROLES)
    small = rep.load(ROOT / "protocols/reproduce.toml")
    n_delays = len(small.config.grid["scene.fri.command_delay_cycles"])  # type: ignore[arg-type]
    assert len(small.scenes) == 1 + n_delays * small.config.sample  # type: ignore[operator]
    assert [s.name for s in small.searches] == ["k_xp", "k_yp", "f_ref I", "f_ref II"]
    nominal = load_scene(ROOT / "data/scenes/paper.toml")
    # every scene of the feasibility box is within the paper's impulse test
    for scene in small.scenes:
        target = nominal.target.model_copy(update={
            "mu": scene.get("scene.target.mu", nominal.target.mu),
            "hose": nominal.target.hose.model_copy(update={
                "stiffness": scene.get("scene.target.hose.stiffness",
                                       nominal.target.hose.stiffness),
                "damping": scene.get("scene.target.hose.damping", nominal.target.hose.damping),
            })})
        assert target.impulse_test_deceleration() <= IMPULSE_TEST_MU_BOUND * 9.81
    big = rep.load(ROOT / "protocols/robustness.toml")
    assert len(big.scenes) == 1 + big.config.sample  # type: ignore[operator]
    lat = [s["scene.target.lateral"] for s in big.scenes[1:]]
    assert nominal.target.lateral - 0.004 <= min(lat) < max(lat) <= nominal.target.lateral + 0.004
    mass = [s["scene.target.mass"] for s in big.scenes[1:]]
    assert nominal.target.mass - 1.0 <= min(mass) < max(mass) <= nominal.target.mass + 1.0
    fric = rep.load(ROOT / "protocols/robustness_friction.toml")
    ends = sorted(s["scene.arm.friction_scale"] for s in fric.scenes[1:])
    assert ends == pytest.approx([nominal.arm.friction_scale * k for k in (0.85, 1.15)])


def test_relative_values_start_from_the_nominal_one(tmp_path: Path) -> None:
    body = ('name = "x"\nsample = 4\n[ranges]\n"scene.target.yaw_deg" = { offset = [-1, 1] }\n'
            '[grid]\n"approach.speed_mps" = { scale = [0.5, 2.0] }\n'
            '"scene.target.mass" = { offset = [0.0] }')
    study = rep.load(_config(tmp_path, body))
    i1 = study.targets["I-1"]
    yaw = i1.scene.target.yaw_deg
    assert all(yaw - 1 <= s["scene.target.yaw_deg"] <= yaw + 1 for s in study.scenes[1:])
    assert sorted({s["approach.speed_mps"] for s in study.scenes[1:]}) == pytest.approx(
        [i1.protocol.approach.speed_mps * 0.5, i1.protocol.approach.speed_mps * 2.0])
    assert {s["scene.target.mass"] for s in study.scenes[1:]} == {i1.scene.target.mass}


@pytest.mark.slow
def test_tiny_study_end_to_end(tmp_path: Path) -> None:
    body = ('name = "tiny"\nseeds = [1, 2]\n[grid]\n"scene.target.lateral" = [0.010, 0.014]\n'
            '"scene.target.mu" = [0.004]\n'
            '[[limits]]\nname = "k_xp"\nrun = "I-1"\nkey = "align.k_ri[3]"\n'
            'range = [0.0, 2.0]\nresolution = 1.0\npaper = [0.5, 2.0]\ncoarse = 3')
    study = rep.load(_config(tmp_path, body), ["run.timeout_s=0.4"])
    assert len(study.scenes) == 3  # the nominal scene and the grid
    out = tmp_path / "out"
    with ThreadPoolExecutor(2) as ex, engine.Runner(out, ex, 2) as r:
        result = rep.run(study, r)
        rep.write(study, result, r.out_dir)
    scenes = pd.read_csv(out / "scenes.csv")
    assert len(scenes) == 3 * 2  # scenes x seeds
    assert scenes["scene.target.lateral"].isna().sum() == 2  # the nominal scene
    for c in claims.SCENE_CLAIMS:
        assert c.name in scenes
    summary = pd.read_csv(out / "claims.csv")
    assert summary["claim"].tolist() == [c.name for c in claims.SCENE_CLAIMS] + ["k_xp limits"]
    n_claims = len(claims.SCENE_CLAIMS)
    assert (summary["scenes"] + summary["not judged"]).iloc[:n_claims].tolist() == [6] * n_claims
    # each claim's verdict at the nominal scene (scene 0, its two seeds) beside the fraction
    for c in claims.SCENE_CLAIMS:
        at0 = scenes.loc[scenes["scene"] == 0, c.name].dropna().astype(bool).tolist()
        want = sum(at0) > len(at0) / 2 if at0 else None
        got = summary.loc[summary["claim"] == c.name, "nominal"].iloc[0]
        assert (None if pd.isna(got) else bool(got)) == want, c.name
    # 3 scenes x 5 roles x 2 seeds, the limit search's runs (seed 1) on top, each once
    runs = pd.read_parquet(out / "results.parquet")
    assert runs["run_id"].nunique() >= 30 + 3
    assert len(list((out / "runs").glob("*/row.json"))) == runs["run_id"].nunique()
    data = json.loads((out / "reproduce.json").read_text())
    assert data["kind"] == "reproduce" and len(data["summary"]) == n_claims + 1
    assert (out / "figures" / "claims.png").is_file()
    assert (out / "figures" / "scenes.png").is_file()  # outcomes over the two grid keys
    flips = pd.read_csv(out / "flips.csv")
    assert len(flips) == 5 + n_claims and set(flips["pairs"]) <= {0, 1}  # 2 x 1 grid: 1 pair


# -- the time left counts the runs the searches will add; a signal stops, never fails ----------
TINY = ('name = "tiny"\nseeds = [1, 2]\n[grid]\n"scene.target.lateral" = [0.010, 0.014]\n'
        '[[limits]]\nname = "k_xp"\nrun = "I-1"\nkey = "align.k_ri[3]"\n'
        'range = [0.0, 2.0]\nresolution = 0.125\ncoarse = 5')


@pytest.mark.parametrize("threshold", [0.1, 0.7, 1.3, 1.9])
def test_a_search_budget_is_what_a_one_limit_search_runs(tmp_path: Path, threshold: float
                                                          ) -> None:
    """The budget of a limit search (coarse grid, one bracket bisected to the resolution)
    is the number of points ``limits.search`` evaluates when the outcome changes once."""
    from ffexp.sweeps import limits

    study = rep.load(_config(tmp_path, TINY))
    (search,) = study.searches
    evaluated: list[limits.Coords] = []

    def evaluate(points: list[limits.Coords]) -> list[float]:
        evaluated.extend(points)
        return [float(p[0] > threshold) for p in points]

    limits.search(evaluate, search.segments(), coarse=search.coarse,
                  resolution=search.resolution)
    # 5 coarse points (0.5 apart), then 0.25, 0.125: two bisections, two seeds each
    assert rep.search_budget(search) == len(evaluated) * len(search.seeds) == (5 + 2) * 1
    assert rep.planned_runs(study) == 3 * 5 * 2 + 7  # scenes x roles x seeds + the search


def test_the_time_left_counts_the_planned_runs() -> None:
    c = engine.Counts(total=10, done=4, running=2, planned=30, run_s=4 * 3.0, slots=2)
    # (30 planned - 4 done - 2 running / 2) runs x 3 s a run / 2 at once
    assert engine.eta_s(c, started=0.0, now=100.0) == pytest.approx(25 * 3.0 / 2)
    c.planned = 0  # no plan: what was submitted
    assert engine.eta_s(c, started=0.0, now=100.0) == pytest.approx(5 * 3.0 / 2)
    assert engine.eta_s(engine.Counts(total=5), started=0.0) is None  # nothing ran yet


def test_the_runner_is_told_the_plan_before_the_runs(tmp_path: Path) -> None:
    study = rep.load(_config(tmp_path, TINY), ["run.timeout_s=0.2"])
    seen: list[engine.Counts] = []
    with ThreadPoolExecutor(2) as ex, engine.Runner(
            tmp_path / "out", ex, 2, on_change=lambda c: seen.append(engine.Counts(**vars(c)))
    ) as r:
        study.scenes = study.scenes[:1]  # the nominal scene only: quick
        rep.run(study, r)
    planned = 1 * 5 * 2 + rep.search_budget(study.searches[0])
    assert seen[0].planned == planned and seen[0].total == 0  # told first
    assert r.counts.done == r.counts.total  # every run it made is counted
    assert r.counts.planned == 0  # at the end the runs made are the plan


@pytest.mark.slow
def test_runs_stopped_by_sigterm_are_stopped_not_failed(tmp_path: Path) -> None:
    """SIGTERM to the process group (as a service manager sends it): the workers ignore
    it, the sweep stops submitting; a second one ends the running runs: they are
    "stopped", none "failed", nothing of them is kept, exit 143."""
    import os
    import re
    import signal
    import subprocess
    import sys

    out = tmp_path / "s"
    proc = subprocess.Popen(
        [sys.executable, "-m", "ffexp", "sweep", str(ROOT / "protocols/method1_case1.toml"),
         "--vary", "align.k_ri[3]=0.25,0.5,0.75", "--set", "run.timeout_s=120",
         "--set", "approach.speed_mps=0.002", "--executor", "local:2", "--out", str(out),
         "--no-figures"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)}, start_new_session=True)
    lines: list[str] = []
    sent = 0  # each signal once, on its line: a progress line printed before the sweep
    # handled the first must not become a second signal (a busy machine delays handling)
    try:
        assert proc.stderr is not None
        for line in proc.stderr:
            lines.append(line.rstrip())
            if sent == 0 and re.search(r", [12] running,", line):
                os.killpg(proc.pid, signal.SIGTERM)  # stop submitting
                sent = 1
            elif sent == 1 and line.startswith("stopping: waiting for the "):
                os.killpg(proc.pid, signal.SIGTERM)  # end the running runs
                sent = 2
        proc.wait(120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    text = "\n".join(lines)
    assert proc.returncode == 143, text
    assert "Traceback" not in text and "error:" not in text, text
    final = [x for x in lines if " done, " in x][-1]
    # the runs the pool had taken when the first signal came (its call queue holds up to
    # three; how many it took by then is the pool's thread's pace) are stopped, the others
    # were never started: none done, none failed, none left running
    found = re.search(r"^sweep method1_case1: 0/([123]) done, 0 running, 0 failed, ([123]) "
                      "stopped,", final)
    assert found is not None and int(found.group(2)) <= int(found.group(1)), final
    assert "stopped; finished runs are kept" in text
    assert not list((out / "runs").glob("*/row.json"))  # no stopped run counts as done


def test_claims_read_the_outcome_rule_when_the_row_has_one() -> None:
    """A row with an ``outcome`` is judged by it: a seat is not enough for III to fail its
    claim, a jam is what II at 0.8 N must be, and an aborted run judges nothing."""
    named = {role: {**r, "outcome": name} for (role, r), name in zip(
        paper_like().items(), ("aligned", "aligned", "held contact, did not slide",
                               "aligned", "contact kept breaking"), strict=True)}
    assert claims.ordering(named, S) is True
    seated_iii = {**named, "III": {**named["III"], "aligned": True}}
    assert claims.iii_breaks(seated_iii, S) is True  # the aligned flag is not the outcome
    kept_seat = {**named, "III": {**named["III"], "outcome": "aligned",
                                  "breaks_after_transient": 5}}
    assert claims.iii_breaks(kept_seat, S) is True  # broke again and again, then seated
    clean = {**named, "III": {**named["III"], "outcome": "aligned",
                              "breaks_after_transient": 1}}
    assert claims.iii_breaks(clean, S) is False
    pushed = {**named, "II-0.8": {**named["II-0.8"], "outcome": "pushed away"}}
    assert claims.ii_low_fails(pushed, S) is False
    aborted = {**named, "III": {**named["III"], "outcome": "aborted"}}
    assert claims.iii_breaks(aborted, S) is None and claims.ordering(aborted, S) is None


def test_ending_the_workers_settles_every_run_before_it_returns() -> None:
    """``end_workers`` (a second signal) returns once the pool's manager thread has ended,
    so every run's future is settled and the pool's wake-up pipe closed, however slow
    that thread is: no bound on the wait (a bound raced on a loaded machine, and the
    interpreter's exit hook, which writes to that pipe, printed 'Bad file descriptor')."""
    import multiprocessing
    import signal
    from concurrent.futures import ProcessPoolExecutor
    from concurrent.futures.process import BrokenProcessPool

    from ffexp.sweeps.executors import end_workers

    pool = ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("forkserver"))
    futures = [pool.submit(signal.pause) for _ in range(3)]  # blocks until killed
    manager = pool._executor_manager_thread  # type: ignore[attr-defined]
    end_workers(pool)
    assert all(f.done() for f in futures)  # none left to settle after it returned
    assert all(f.cancelled() or isinstance(f.exception(), BrokenProcessPool) for f in futures)
    assert manager is not None and not manager.is_alive()
