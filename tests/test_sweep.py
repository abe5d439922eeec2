"""``ffexp sweep``: keys and overrides, run ids, the grid's rows and files, resume, bad input.

The simulator is being changed by others: nothing here depends on a run's
outcome. Runs are short (``run.timeout_s`` below a second); the engine tests
use a thread pool in this process (same code path as the process pool,
without its start-up cost); the CLI tests use the process pool.
"""

from __future__ import annotations

import functools
import json
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import pandas as pd
import pytest
from typer.testing import CliRunner

from ffexp.cli import app
from ffexp.errors import ConfigError
from ffexp.sweeps import engine, keys, plan, table
from ffexp.sweeps.grid import execute, prepare
from ffexp.sweeps.worker import RUNS_DIR, TMP_PREFIX

ROOT = Path(__file__).resolve().parents[1]
P1 = ROOT / "protocols/method1_case1.toml"
SHORT = "run.timeout_s=0.4"
VARY = ["align.k_ri[3]=0.25,0.5", "scene.target.lateral=0.010,0.012,0.014"]
cli = CliRunner()


# -- keys and overrides (pure) ---------------------------------------------------------
def test_keys_scene_index_and_protocol() -> None:
    k = keys.parse_key("scene.target.lateral")
    assert (k.scene, k.dotted, k.index) == (True, "target.lateral", None)
    k = keys.parse_key("align.k_ri[3]")
    assert (k.scene, k.dotted, k.index) == (False, "align.k_ri", 3)
    k = keys.parse_key("scene.file")  # the protocol's own field, not a scene key
    assert not k.scene
    for bad in ("align..kp", "align.kp[x]", "3abc", "seed"):
        with pytest.raises(ConfigError):
            keys.parse_key(bad)


def test_values_are_toml_and_one_numeric_type() -> None:
    assert keys.parse_values("0,0.5,1") == [0.0, 0.5, 1.0]
    assert all(isinstance(v, float) for v in keys.parse_values("0,0.5,1"))
    assert keys.parse_values("1,2") == [1, 2]
    assert keys.parse_values("[0,0,1],[0,0,2]") == [[0, 0, 1], [0, 0, 2]]
    assert keys.parse_values("force,impedance") == ["force", "impedance"]
    with pytest.raises(ConfigError):
        keys.parse_values("")
    with pytest.raises(ConfigError, match="empty range"):
        keys.parse_range("align.kp=2:1")


def test_point_overrides_merge_index_keys_and_extend_scene_set() -> None:
    ks = [keys.parse_key(t) for t in ("align.k_ri[1]", "align.k_ri[3]", "scene.target.mu",
                                      "approach.speed_mps")]
    base = {"align": {"k_ri": [0.0, 0.2, 0.0, 0.5, 0.0, 0.0]}}
    sets = keys.point_overrides(
        ks, {"align.k_ri[1]": 1.0, "align.k_ri[3]": 2.0, "scene.target.mu": 0.003,
             "approach.speed_mps": 0.01}, base, {}, ["target.lateral=0.01"])
    assert "approach.speed_mps=0.01" in sets
    assert "align.k_ri=[0.0, 1.0, 0.0, 2.0, 0.0, 0.0]" in sets
    assert 'scene.set=["target.lateral=0.01", "target.mu=0.003"]' in sets
    assert base["align"]["k_ri"][1] == 0.2  # the base is not modified


def test_run_id_is_canonical() -> None:
    a = keys.run_id("p:1", {"x": 0.5, "y": 1.0}, 1, ())
    assert a == keys.run_id("p:1", {"y": 1.0, "x": 0.5}, 1, ())  # key order does not matter
    others = {keys.run_id("p:1", {"x": 0.5, "y": 1.0}, 2, ()),
              keys.run_id("p:2", {"x": 0.5, "y": 1.0}, 1, ()),
              keys.run_id("p:1", {"x": 0.25, "y": 1.0}, 1, ()),
              keys.run_id("p:1", {"x": 0.5, "y": 1.0}, 1, ("run.timeout_s=1",))}
    assert a not in others and len(others) == 4


def test_target_puts_a_point_into_the_protocol_and_scene(tmp_path: Path) -> None:
    from drivers.description.scene import load_scene
    from ffexp.protocol import load_run_protocol

    t = plan.Target(P1, (SHORT,))
    ks = [keys.parse_key(v.split("=")[0]) for v in VARY]
    point = {"align.k_ri[3]": 0.25, "scene.target.lateral": 0.014}
    proto = load_run_protocol(P1, t.overrides(ks, point))
    assert proto.align.k_ri[3] == 0.25 and proto.align.k_ri[1] == t.protocol.align.k_ri[1]
    assert proto.run.timeout_s == 0.4
    scene = load_scene(ROOT / "data/scenes/paper.toml", proto.scene.set)
    assert scene.target.lateral == 0.014


def test_latin_hypercube_one_point_per_stratum() -> None:
    ks = [keys.parse_key("scene.target.mu"), keys.parse_key("scene.target.lateral")]
    pts = plan.latin_hypercube([(ks[0], 0.0, 1.0), (ks[1], 10.0, 20.0)], 8, seed=3)
    assert pts == plan.latin_hypercube([(ks[0], 0.0, 1.0), (ks[1], 10.0, 20.0)], 8, seed=3)
    for key, lo, hi in (("scene.target.mu", 0.0, 1.0), ("scene.target.lateral", 10.0, 20.0)):
        strata = sorted(int((p[key] - lo) / (hi - lo) * 8) for p in pts)
        assert strata == list(range(8))


# -- the engine --------------------------------------------------------------------------
def _prep() -> Any:
    return prepare(P1, vary=VARY, seeds=2, fixed=[SHORT])


def _counting(calls: dict[str, int]) -> Any:
    real = engine.run_one

    @functools.wraps(real)
    def wrapped(job: Any) -> dict[str, Any]:
        calls[job.run_id] = calls.get(job.run_id, 0) + 1
        return real(job)

    return wrapped


def test_grid_rows_files_heatmap_and_resume_after_a_stop(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """2x3 grid, 2 seeds: stopped after 5 runs, started again: 12 rows, 12 files, the
    heat map, no duplicate, no run done twice."""
    calls: dict[str, int] = {}
    monkeypatch.setattr(engine, "run_one", _counting(calls))
    prep = _prep()
    stop = {"now": False}

    def on_change(c: engine.Counts) -> None:
        if c.done >= 5:
            stop["now"] = True

    with ThreadPoolExecutor(2) as ex, engine.Runner(
            tmp_path, ex, 2, on_change=on_change, stop_requested=lambda: stop["now"]) as r:
        with pytest.raises(engine.Stopped):
            execute(prep, r)
    first = {p.name: (p / "row.json").stat().st_mtime_ns
             for p in (tmp_path / RUNS_DIR).iterdir()}
    assert 5 <= len(first) < 12
    assert not list((tmp_path / RUNS_DIR).glob(f"{TMP_PREFIX}*"))
    with ThreadPoolExecutor(2) as ex, engine.Runner(tmp_path, ex, 2) as r:
        result = execute(prep, r)
    rows = result["rows"]
    assert len(rows) == 12 and len({row["run_id"] for row in rows}) == 12
    assert sorted(calls.values()) == [1] * 12  # every run exactly once over both sessions
    for name, mtime in first.items():  # the runs of the first session were not redone
        assert (tmp_path / RUNS_DIR / name / "row.json").stat().st_mtime_ns == mtime
    mcaps = sorted((tmp_path / RUNS_DIR).glob("*/run.mcap"))
    assert len(mcaps) == 12
    df = pd.read_parquet(tmp_path / "results.parquet")
    assert len(df) == 12 and df["run_id"].is_unique
    assert pd.read_csv(tmp_path / "results.csv")["run_id"].tolist() == df["run_id"].tolist()
    assert sorted(set(df["align.k_ri[3]"])) == [0.25, 0.5]
    assert sorted(set(df["scene.target.lateral"])) == [0.010, 0.012, 0.014]
    assert sorted(set(df["seed"])) == [1, 2]
    for col in ("align.k_ri[3]", "duration_s", "wall_s", "contact_breaks",
                "mean_fz_align_n"):
        assert pd.api.types.is_numeric_dtype(df[col]), col
    for rel in df["path"]:
        assert (tmp_path / rel).is_file()
    assert (tmp_path / "figures" / "heatmap.png").stat().st_size > 1000
    # the recording of a row is the run of that row's values
    from ffexp.recording import load

    row = df.iloc[0]
    meta = load(tmp_path / row["path"]).metadata["run"]
    proto = json.loads(meta["protocol_json"])
    assert proto["align"]["k_ri"][3] == row["align.k_ri[3]"]
    assert proto["seed"] == row["seed"]
    # a third time: nothing runs
    n = len(calls)
    with ThreadPoolExecutor(2) as ex, engine.Runner(tmp_path, ex, 2) as r:
        again = execute(prep, r, figures=False)["rows"]
    assert len(calls) == n and sorted(calls.values()) == [1] * 12
    assert table.without_wall_time(again) == table.without_wall_time(rows)


def test_a_failing_run_is_a_row_with_its_error(tmp_path: Path) -> None:
    prep = prepare(P1, vary=["align.k_ri[3]=0.5"], fixed=[SHORT])
    with ThreadPoolExecutor(1) as ex, engine.Runner(tmp_path, ex, 1) as r:
        jobs = prep.jobs(r.out_dir)
    bad = [type(j)(j.run_id, str(tmp_path / "gone.toml"), j.overrides, j.out_dir, j.columns)
           for j in jobs]
    with ThreadPoolExecutor(1) as ex, engine.Runner(tmp_path, ex, 1) as r:
        rows = r.run_batch(bad)
    assert len(rows) == 1 and "gone.toml" in rows[0]["error"]
    assert rows[0]["path"] is None and "aligned" not in rows[0]
    df = table.frame(rows)
    assert df["error"].iloc[0] == rows[0]["error"]


def test_leftovers_of_a_killed_run_do_not_count_and_are_removed(tmp_path: Path) -> None:
    prep = prepare(P1, vary=["align.k_ri[3]=0.5"], fixed=[SHORT])
    with ThreadPoolExecutor(1) as ex, engine.Runner(tmp_path, ex, 1) as r:
        job = prep.jobs(r.out_dir)[0]
    half = tmp_path / RUNS_DIR / f"{TMP_PREFIX}{job.run_id}-host-1-abcdef"
    half.mkdir()
    (half / "run.mcap").write_bytes(b"\x89MCAP0\r\n")  # cut short
    calls: dict[str, int] = {}
    with ThreadPoolExecutor(1) as ex, engine.Runner(tmp_path, ex, 1) as r:
        assert not half.exists()
        real = engine.run_one
        try:
            engine.run_one = _counting(calls)  # type: ignore[assignment]
            rows = r.run_batch([job])
        finally:
            engine.run_one = real  # type: ignore[assignment]
    assert calls == {job.run_id: 1} and rows[0]["error"] is None


def test_a_second_sweep_into_the_same_directory_is_refused(tmp_path: Path) -> None:
    with ThreadPoolExecutor(1) as ex, engine.Runner(tmp_path, ex, 1), pytest.raises(
            ConfigError, match="another sweep"):
        engine.Runner(tmp_path, ex, 1).open()


# -- the command --------------------------------------------------------------------------
@pytest.mark.slow
def test_cli_sweep_grid_on_the_process_pool(tmp_path: Path) -> None:
    out = tmp_path / "s"
    args = ["sweep", str(P1), "--vary", VARY[0], "--vary", VARY[1], "--seeds", "2",
            "--set", SHORT, "--executor", "local:2", "--out", str(out), "--json"]
    res = cli.invoke(app, args)
    assert res.exit_code == 0, res.output
    lines = [json.loads(x) for x in res.stdout.splitlines() if x.startswith("{")]
    assert len(lines) == 12 and len({r["run_id"] for r in lines}) == 12
    assert len(list((out / RUNS_DIR).glob("*/run.mcap"))) == 12
    assert (out / "figures" / "heatmap.png").is_file()
    one = cli.invoke(app, ["sweep", str(P1), "--vary", VARY[0], "--set", SHORT,
                           "--executor", "local:1", "--out", str(tmp_path / "one")])
    assert one.exit_code == 0 and (tmp_path / "one" / "figures" / "lines.png").is_file()
    lhs = cli.invoke(app, ["sweep", str(P1), "--sample", "3", "--range",
                           "scene.target.mu=0.002:0.009", "--set", SHORT, "--executor",
                           "local:1", "--out", str(tmp_path / "lhs"), "--no-figures"])
    assert lhs.exit_code == 0, lhs.output
    mu = pd.read_csv(tmp_path / "lhs" / "results.csv")["scene.target.mu"]
    assert len(set(mu)) == 3 and all(0.002 <= m <= 0.009 for m in mu)
    # one value per third of the range (Latin hypercube)
    assert sorted(int((m - 0.002) / 0.007 * 3) for m in mu) == [0, 1, 2]


BAD = [
    (["--vary", "align.nope=1,2"], ["--vary", "align.nope", "unknown key"]),
    (["--vary", "scene.target.nope=1"], ["--vary", "target.nope", "unknown key"]),
    (["--vary", "align.kp=abc"], ["--vary", "align.kp"]),
    (["--vary", "scene.target.lateral=x"], ["--vary", "target.lateral", "number"]),
    (["--vary", "align.k_ri[9]=1"], ["--vary", "align.k_ri[9]", "past the end"]),
    (["--vary", "align.kp="], ["--vary", "no values"]),
    (["--sample", "3", "--range", "scene.target.mu=0.01:0.001"], ["--range", "empty range"]),
    (["--sample", "3", "--range", "scene.target.mu=1:x"], ["--range", "LO:HI"]),
    (["--range", "align.kp=1:2"], ["--range", "--sample"]),
    (["--sample", "0", "--range", "scene.target.mu=0:1"], ["--sample"]),
    (["--seeds", "0"], ["--seeds"]),
    (["--executor", "foo"], ["--executor", "foo"]),
    (["--executor", "local:0"], ["--executor", "local:0"]),
    (["--executor", "ray:127.0.0.1:1"], ["--executor", "127.0.0.1:1", "not reachable"]),
    (["--executor", "ray:host"], ["--executor", "ray:host"]),
]


@pytest.mark.parametrize(("extra", "needles"), BAD, ids=[" ".join(b[0]) for b in BAD])
def test_bad_input_one_line_exit_2_before_any_run(
    tmp_path: Path, extra: list[str], needles: list[str]
) -> None:
    out = tmp_path / "never"
    res = cli.invoke(app, ["sweep", str(P1), *extra, "--out", str(out)])
    assert res.exit_code == 2, res.output
    err = res.stderr.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: "), res.stderr
    for n in needles:
        assert n in err[0]
    assert "Traceback" not in res.output
    assert not out.exists()  # nothing ran, nothing was created


def test_bad_input_as_a_subprocess(tmp_path: Path) -> None:
    res = subprocess.run(
        [sys.executable, "-m", "ffexp", "sweep", str(P1), "--vary", "align.nope=1",
         "--out", str(tmp_path / "x")], capture_output=True, text=True, timeout=120)
    assert res.returncode == 2
    assert res.stderr.strip().splitlines() == [
        res.stderr.strip()] and "align.nope" in res.stderr and "Traceback" not in res.stderr
