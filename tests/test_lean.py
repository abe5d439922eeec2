"""Lean recordings: the same rows as a full recording, fewer messages built, said in the
file; studies that ask for them cache by run id without mixing lean and full silently;
commands that need a topic a lean file lacks refuse it in one line.

Every run here is compared with itself recorded the other way (same protocol, seed and
simulator), so nothing depends on what a run's outcome is.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

from ffexp import runlog
from ffexp.analysis import metrics
from ffexp.cli import app
from ffexp.experiment import run_file
from ffexp.recording import Recorder, Recording, load
from ffexp.recording.batch import RECORDING_METADATA, is_lean, lean_topic, missing_topic
from ffexp.sweeps import engine
from ffexp.sweeps.grid import execute, prepare
from ffexp.sweeps.worker import RUNS_DIR, Job, flat_metrics, read_row, serves

ROOT = Path(__file__).resolve().parents[1]
PROTOCOLS = ROOT / "protocols"
cli = CliRunner()
#: Methods I, II and III through contact and into ALIGN, a run the workspace limit aborts
#: after contact, and a 6-DOF run on the zero-g scene (a floating target's truth).
CASES = [
    ("method1_case1", ["run.timeout_s=5"]),
    ("method2", ["run.timeout_s=5"]),
    ("method3_impedance", ["run.timeout_s=5"]),
    ("method1_case1", ["run.timeout_s=6", "limits.workspace_m=[0.05, 0.15, 0.08]"]),
    ("sixdof_method1", ["run.timeout_s=4.5"]),
]


def _both(tmp_path: Path, name: str, overrides: list[str]) -> tuple[Recording, Recording]:
    full = run_file(PROTOCOLS / f"{name}.toml", overrides, out_dir=tmp_path / "full")
    lean = run_file(PROTOCOLS / f"{name}.toml", overrides, out_dir=tmp_path / "lean",
                    lean=True)
    return load(full.path), load(lean.path)


@pytest.mark.parametrize(("name", "overrides"), CASES,
                         ids=["method1", "method2", "method3", "aborted", "sixdof"])
def test_a_lean_runs_row_is_the_full_runs_row(tmp_path: Path, name: str,
                                              overrides: list[str]) -> None:
    full, lean = _both(tmp_path, name, overrides)
    row_full, row_lean = flat_metrics(metrics(full)), flat_metrics(metrics(lean))
    assert row_lean == row_full
    assert row_full["first_contact_s"] is not None  # each case reaches contact
    if name.startswith("method") and not any(o.startswith("limits.") for o in overrides):
        assert row_full["mean_fz_align_n"] is not None  # and ALIGN
    if any(o.startswith("limits.") for o in overrides):
        assert row_full["aborted"] and "workspace limit" in row_full["aborted"]
    # the file says what it is; a full file is as before (no such metadata)
    assert is_lean(lean.metadata) and lean.metadata[RECORDING_METADATA]["lean"] == "true"
    assert RECORDING_METADATA not in full.metadata and not is_lean(full.metadata)
    kept = lean.metadata[RECORDING_METADATA]["topics"].split(",")
    assert "/estimator/state" in kept and "/sim/*" in kept and "/ft/raw" not in kept
    # only kept topics, each message the full file's, at the same run time
    have = [*lean.topics, *lean.json]
    assert have and all(lean_topic(t, "/sim") for t in have)
    assert {"/ft/raw", "/control/command"} <= set(full.topics)
    assert "/tf" in full.json and "/tf" not in lean.json
    assert not any(t.startswith("/scene") for t in have)
    assert any(t.startswith("/scene") for t in full.json)
    assert set(full.topics) - set(lean.topics)  # something was left out
    for topic, data in lean.topics.items():
        other = full.topic(topic)
        assert np.array_equal(data.log_time_ns - lean.run_start_ns,
                              other.log_time_ns - full.run_start_ns), topic
        for f in data.fields:
            assert data[f].tobytes() == other[f].tobytes(), (topic, f)


def test_a_lean_run_log_builds_no_message_it_does_not_keep(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """No /tf, no command, no F/T sample, no 3-D scene encoded; fields encoded only for
    kept topics (the CPU is saved, not just the bytes)."""
    encoded: list[str] = []
    calls = {"transform": 0, "command": 0, "rows": 0}
    real_encoder = Recorder.encoder

    def encoder(self: Recorder, topic: str) -> Callable[[object], bytes]:
        fn = real_encoder(self, topic)

        def counted(source: object) -> bytes:
            encoded.append(topic)
            return fn(source)
        return counted

    def count(key: str, real: Any) -> Any:
        def wrapped(*args: Any, **kwargs: Any) -> Any:
            calls[key] += 1
            return real(*args, **kwargs)
        return wrapped

    monkeypatch.setattr(Recorder, "encoder", encoder)
    monkeypatch.setattr(Recorder, "encode_transform", count("transform",
                                                             Recorder.encode_transform))
    monkeypatch.setattr(Recorder, "write_rows", count("rows", Recorder.write_rows))
    monkeypatch.setattr("ffexp.runlog.command_message",
                        count("command", runlog.command_message))

    def no_scene(*_args: object, **_kw: object) -> None:
        raise AssertionError("a lean run built the 3-D scene")

    monkeypatch.setattr("ffexp.scene3d.SceneWriter.__init__", no_scene)
    run_file(PROTOCOLS / "method1_case1.toml", ["run.timeout_s=4.5"], out_dir=tmp_path,
             lean=True)
    assert calls == {"transform": 0, "command": 0, "rows": 0}
    assert encoded and all(lean_topic(t, "/sim") for t in encoded)
    assert "/robot/measurement" not in encoded and "/robot/link" in encoded
    monkeypatch.undo()
    monkeypatch.setattr(Recorder, "encode_transform", count("transform",
                                                             Recorder.encode_transform))
    run_file(PROTOCOLS / "method1_case1.toml", ["run.timeout_s=0.5"], out_dir=tmp_path / "f")
    assert calls["transform"] > 0  # the same counter sees a full run's /tf


def test_lean_keeps_the_metrics_topics_and_every_scenarios_measures() -> None:
    for topic in ("/estimator/state", "/control/terms", "/robot/state", "/runner/phase",
                  "/robot/link", "/task/funnel", "/task/docking6"):
        assert lean_topic(topic), topic
    for topic in ("/ft/raw", "/control/command", "/robot/measurement", "/robot/command",
                  "/scene/rig"):
        assert not lean_topic(topic, "/sim"), topic


def test_serves_full_always_lean_only_for_lean() -> None:
    lean_job, full_job = (Job("a", "p.toml", (), "out", lean=True), Job("a", "p.toml", (), "out"))
    assert serves({"recording": "full"}, lean_job) and serves({"recording": "full"}, full_job)
    assert serves({"recording": "lean"}, lean_job)
    assert not serves({"recording": "lean"}, full_job)
    assert serves({}, full_job)  # a row from before lean recordings: full


def test_a_row_from_before_lean_recordings_reads_as_full(tmp_path: Path) -> None:
    (tmp_path / RUNS_DIR / "abc").mkdir(parents=True)
    (tmp_path / RUNS_DIR / "abc" / "row.json").write_text(json.dumps({"run_id": "abc"}))
    assert read_row(tmp_path, "abc") == {"run_id": "abc", "recording": "full"}


def _study(tmp_path: Path, lean: bool, calls: list[str]) -> list[dict[str, Any]]:
    prep = prepare(PROTOCOLS / "method1_case1.toml", vary=["align.k_ri[3]=0.25,0.5"],
                   fixed=["run.timeout_s=0.4"])
    with ThreadPoolExecutor(2) as ex, engine.Runner(
            tmp_path, ex, 2, lean=lean, on_change=lambda c: calls.append(
                f"{c.done - c.skipped}")) as r:
        rows: list[dict[str, Any]] = execute(prep, r, figures=False)["rows"]
    return rows


def test_a_study_caches_lean_and_full_by_run_id_without_mixing(tmp_path: Path) -> None:
    """Lean first; full asked: each lean run runs again and is replaced by its full one
    (the same numbers); lean asked again: the full runs serve, nothing runs."""
    calls: list[str] = []
    lean_rows = _study(tmp_path, True, calls)
    assert [r["recording"] for r in lean_rows] == ["lean", "lean"]
    assert json.loads((tmp_path / "sweep.json").read_text())["recording"] == "lean"
    for row in lean_rows:
        assert is_lean(load(tmp_path / row["path"]).metadata)
    calls.clear()
    full_rows = _study(tmp_path, False, calls)
    assert calls[-1] == "2"  # both ran again
    assert [r["recording"] for r in full_rows] == ["full", "full"]
    for row in full_rows:
        assert not is_lean(load(tmp_path / row["path"]).metadata)
    assert sorted(p.name for p in (tmp_path / RUNS_DIR).iterdir()) == sorted(
        r["run_id"] for r in lean_rows)  # replaced, nothing left aside

    def numbers(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
        return [{k: v for k, v in r.items() if k not in ("wall_s", "recording")}
                for r in rows]

    assert numbers(full_rows) == numbers(lean_rows)
    calls.clear()
    again = _study(tmp_path, True, calls)
    assert calls[-1] == "0"  # the full runs serve a lean study
    assert [r["recording"] for r in again] == ["full", "full"]
    assert json.loads((tmp_path / "sweep.json").read_text())["recording"] == "lean"


def test_commands_that_need_a_left_out_topic_refuse_a_lean_file(tmp_path: Path) -> None:
    lean = run_file(PROTOCOLS / "method1_case1.toml", ["run.timeout_s=0.5"],
                    out_dir=tmp_path, lean=True).path
    for words, topic in ((["replay", str(lean), "--out", str(tmp_path / "r.mcap")], "/ft/raw"),
                         (["resimulate", str(lean), "--out", str(tmp_path / "s.mcap")],
                          "/robot/command")):
        res = cli.invoke(app, words)
        assert res.exit_code == 2, res.output
        err = res.stderr.strip().splitlines()
        assert len(err) == 1 and err[0].startswith(f"error: {lean}: a lean recording")
        assert topic in err[0]
        assert not (tmp_path / "r.mcap").exists()
    # a full file never had a topic it lacks: no lean message for it
    rec = load(lean)
    assert missing_topic(lean, {}, rec.topics, ["/ft/raw"]) is None
    assert missing_topic(lean, rec.metadata, rec.topics, ["/estimator/state"]) is None
    # what reads only the metrics' topics works on it
    assert cli.invoke(app, ["analyze", str(lean), "--json"]).exit_code in (0, 3, 4)


def test_cli_run_and_sweep_say_lean(tmp_path: Path) -> None:
    res = cli.invoke(app, ["run", str(PROTOCOLS / "method1_case1.toml"), "--set",
                           "run.timeout_s=0.4", "--lean", "--out", str(tmp_path / "r")])
    assert res.exit_code in (0, 4), res.output
    (path,) = (tmp_path / "r").glob("*.mcap")
    assert is_lean(load(path).metadata)
    res = cli.invoke(app, ["sweep", str(PROTOCOLS / "method1_case1.toml"), "--vary",
                           "align.k_ri[3]=0.5", "--set", "run.timeout_s=0.4", "--executor",
                           "local:1", "--no-figures", "--lean", "--out", str(tmp_path / "s")])
    assert res.exit_code == 0, res.output
    assert "lean recordings" in res.output
    assert json.loads((tmp_path / "s" / "sweep.json").read_text())["recording"] == "lean"
    header, row = (tmp_path / "s" / "results.csv").read_text().splitlines()[:2]
    assert header.split(",")[-1] == "recording" and row.split(",")[-1] == "lean"
