"""``ffexp analyze``, ``compare``, ``recover`` and ``topics`` through the CLI."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest
from mcap.writer import Writer
from typer.testing import CliRunner

from ffexp.cli import app

ROOT = Path(__file__).resolve().parents[1]
runner = CliRunner()


@pytest.fixture(scope="module")
def run_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("runs")
    result = runner.invoke(
        app,
        ["run", str(ROOT / "protocols/method1_case2.toml"), "--set", "run.timeout_s=1.0",
         "--out", str(out)],
    )
    assert result.exit_code == 4, result.stderr  # timed out without aligning
    (path,) = out.glob("*.mcap")
    assert f"recording: {path}" in result.stdout
    return path


def test_analyze_json_has_the_documented_keys(run_file: Path, tmp_path: Path) -> None:
    result = runner.invoke(app, ["analyze", str(run_file), "--json", "--plots", str(tmp_path)])
    assert result.exit_code == 0, result.stderr
    m = json.loads(result.stdout)
    for key in ("protocol", "method", "aligned", "alignment_time_s", "first_contact_s",
                "contact_breaks", "mean_fz_align_n", "peak_abs_fz_n", "fz_tracking_rmse_n",
                "target_speed_after_contact_mps", "aborted"):
        assert key in m
    assert m["protocol"] == "method1_case2" and m["method"] == "force_ri"
    assert isinstance(m["aligned"], bool) and isinstance(m["contact_breaks"], int)
    assert m["aborted"] is None
    # timed out without aligning, judged by the simulator's truth, its evidence recorded
    assert m["verdict"] == "not aligned" and m["verdict_source"] == "truth"
    assert m["verdict_truth"] == "not aligned"
    assert {"lateral_m", "yaw_deg", "insertion_m"} <= set(m["verdict_evidence"])
    # a 1 s run never reaches ALIGN: no ALIGN peak, but the whole run's peak is there
    assert m["peak_abs_fz_n"] is None and m["peak_abs_fz_run_n"] >= 0.0
    assert m["file"] == str(run_file) and m["complete"] is True
    # the in-process link never faults: a valid trial, said in one line
    assert m["measured"] is True and m["trial_valid"] is True
    assert m["link"].startswith("valid trial")
    assert m["run"] == run_file.stem and run_file.stem.startswith("method1_case2-")
    for kind in ("wrench", "applied"):
        assert (tmp_path / f"{run_file.stem}_{kind}.png").read_bytes()[:4] == b"\x89PNG"
        assert b"<svg" in (tmp_path / f"{run_file.stem}_{kind}.svg").read_bytes()[:400]


def test_a_robot_that_never_answered_is_an_abort_and_analyze_says_why(
    tmp_path: Path,
) -> None:
    run = runner.invoke(app, [
        "run", str(ROOT / "protocols/method1_case1.toml"), "--driver", "fri",
        "--robot-ip", "127.0.0.1", "--fri-port", "0", "--ft", "mock",
        "--rig-set", "robot.connect_timeout_s=0.2", "--out", str(tmp_path)])
    assert run.exit_code == 3, run.stdout + run.stderr  # the ABORT code, not a missing topic
    assert "received nothing" in run.stdout and "Traceback" not in run.stdout + run.stderr
    (path,) = tmp_path.glob("*.mcap")
    text = runner.invoke(app, ["analyze", str(path)])
    assert text.exit_code == 0, text.stderr
    assert "no measurement received" in " ".join(text.stdout.split())
    as_json = runner.invoke(app, ["analyze", str(path), "--json"])
    m = json.loads(as_json.stdout)
    assert m["measured"] is False and m["trial_valid"] is False
    assert m["link"].startswith("no measurement received")


def test_compare_writes_csv(run_file: Path, tmp_path: Path) -> None:
    out = tmp_path / "table.csv"
    result = runner.invoke(app, ["compare", str(run_file), str(run_file), "--csv", str(out)])
    assert result.exit_code == 0, result.stderr
    rows = list(csv.DictReader(out.open()))
    assert len(rows) == 2 and rows[0]["protocol"] == "method1_case2"
    assert float(rows[0]["k_yp"]) == 1.0 and float(rows[0]["k_xp"]) == 0.0
    assert rows[0]["file"] == str(run_file) and rows[0]["complete"] == "True"


def test_recover_of_a_finished_file(run_file: Path, tmp_path: Path) -> None:
    out = tmp_path / "copy.mcap"
    result = runner.invoke(app, ["recover", str(run_file), "-o", str(out)])
    assert result.exit_code == 0
    assert "complete file" in result.stdout
    again = runner.invoke(app, ["analyze", str(out), "--json"])
    assert json.loads(again.stdout)["protocol"] == "method1_case2"


def foreign_mcap(path: Path) -> None:
    with path.open("wb") as fh:
        w = Writer(fh)
        w.start()
        sid = w.register_schema("x", "jsonschema", b"{}")
        cid = w.register_channel("/other", "json", sid)
        w.add_message(cid, 1, b"{}", 1)
        w.finish()


@pytest.mark.parametrize(
    ("maker", "message"),
    [
        (lambda p: p.write_bytes(b""), "empty file"),
        (lambda p: p.write_text("not a recording\n"), "not an MCAP file"),
        (foreign_mcap, "no topic /estimator/state"),
        (lambda p: None, "file not found"),
    ],
)
def test_bad_recordings_give_one_line(tmp_path: Path, maker: object, message: str) -> None:
    path = tmp_path / "bad.mcap"
    maker(path)  # type: ignore[operator]
    for cmd in (["analyze", str(path)], ["compare", str(path)]):
        result = runner.invoke(app, cmd)
        assert result.exit_code == 2
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and message in lines[0] and str(path) in lines[0]
        assert "Traceback" not in result.stdout + result.stderr


def test_truncated_recording_gives_partial_results_with_a_warning(
    run_file: Path, tmp_path: Path
) -> None:
    from mcap.reader import make_reader

    with run_file.open("rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None
    first = min(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(run_file.read_bytes()[: first.chunk_start_offset + first.chunk_length + 10])
    result = runner.invoke(app, ["analyze", str(cut), "--json"])
    assert result.exit_code == 0, result.stderr
    assert "incomplete" in result.stderr and str(cut) in result.stderr
    m = json.loads(result.stdout)
    assert m["complete"] is False and m["protocol"] == "method1_case2"


def test_topics_lists_every_topic() -> None:
    from ffexp.recording.topics import CDR_TOPICS, JSON_TOPICS

    result = runner.invoke(app, ["topics", "--wide"])
    assert result.exit_code == 0
    for topic in [*CDR_TOPICS, *JSON_TOPICS]:
        assert topic in result.stdout
    assert "foxglove.FrameTransform" in result.stdout
    assert "Every topic of an ffexp run recording" not in result.stdout  # no docstring


def test_topics_fits_80_columns_and_lists_fields() -> None:
    result = runner.invoke(app, ["topics", "--fields"])
    assert result.exit_code == 0
    assert max(len(line) for line in result.stdout.splitlines()) <= 80
    assert "msr_cart_pos" in result.stdout and "/runner/phase" in result.stdout


def test_topics_of_a_file_counts_its_messages(run_file: Path) -> None:
    from ffexp.recording import load

    rec = load(run_file)
    result = runner.invoke(app, ["topics", str(run_file), "--wide"])
    assert result.exit_code == 0, result.stderr
    assert "complete" in result.stdout
    lines = {line.split("│")[1].strip(): line for line in result.stdout.splitlines()
             if line.count("│") > 2}
    for topic, data in rec.topics.items():
        count = int(lines[topic].split("│")[2])
        assert count == len(data), topic
