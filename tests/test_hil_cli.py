"""``ffexp hil``, ``ffexp hil-sweep`` and ``ffexp analyze --json`` on their recordings,
through typer's CliRunner and once as a subprocess."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from ffexp.cli import app
from ffexp.recording import load

ROOT = Path(__file__).resolve().parents[1]
PROTOCOL = str(ROOT / "protocols/hil_impact.toml")
runner = CliRunner()
KEYS = ("restitution", "loop_delay_s", "effective_mass_kg", "contact_stiffness_npm",
        "contact_damping_nspm")


def test_hil_records_an_impact_that_analyze_reports(tmp_path: Path) -> None:
    res = runner.invoke(app, ["hil", PROTOCOL, "--out", str(tmp_path),
                              "--scene-set", "contact.stiffness=10000"])
    assert res.exit_code == 0, res.output
    path = tmp_path / "hil_impact.mcap"
    assert f"-> {path}" in res.output
    res = runner.invoke(app, ["analyze", "--json", str(path)])
    assert res.exit_code == 0, res.output
    row = json.loads(res.output)
    assert all(row[k] is not None for k in KEYS)
    assert row["contact_stiffness_npm"] == 10000.0
    assert row["restitution"] > row["true_restitution"]  # no compensation: the delay adds
    # a second run does not overwrite the first
    assert runner.invoke(app, ["hil", PROTOCOL, "--out", str(tmp_path)]).exit_code == 0
    assert (tmp_path / "hil_impact-1.mcap").exists()


def test_an_unstable_loop_ends_held_with_one_line_and_exit_3(tmp_path: Path) -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "ffexp", "hil", PROTOCOL, "--out", str(tmp_path),
         "--scene-set", "carrier.extra_delay_cycles=6"],
        capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 3
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("carrier held at ")
    assert "rendering unstable" in lines[0] and "chaser stopped" in lines[0]
    assert "Traceback" not in proc.stderr
    row = json.loads(runner.invoke(app, ["analyze", "--json",
                                         str(tmp_path / "hil_impact.mcap")]).output)
    assert row["restitution"] is None and row["carrier_held"].startswith("carrier: ")


def test_hil_sweep_writes_the_table_and_the_figure(tmp_path: Path) -> None:
    res = runner.invoke(app, ["hil-sweep", PROTOCOL, "--out", str(tmp_path), "--delays", "0,1",
                              "--stiffness", "20000", "--compensation", "none,passivity"])
    assert res.exit_code == 0, res.output
    rows = list(csv.DictReader((tmp_path / "hil_sweep.csv").open()))
    assert [(r["compensation"], r["extra_delay_cycles"]) for r in rows] == [
        ("none", "0"), ("none", "1"), ("passivity", "0"), ("passivity", "1")]
    assert float(rows[1]["restitution"]) > float(rows[0]["restitution"])
    assert (tmp_path / "hil_sweep.png").stat().st_size > 0


@pytest.mark.parametrize(("fault", "cause"), [
    ("faults.link_lost_at_s=0.03", "carrier link lost"),
    ("faults.ft_stale_at_s=0.03", "carrier F/T stale"),
    ("impact.speed_mps=0.6", "carrier speed"),
])
def test_a_fault_ends_the_run_held_with_one_line(tmp_path: Path, fault: str, cause: str) -> None:
    res = runner.invoke(app, ["hil", PROTOCOL, "--out", str(tmp_path), "--set", fault])
    assert res.exit_code == 3
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and cause in lines[0] and "chaser stopped" in lines[0]
    rec = load(tmp_path / "hil_impact.mcap")
    assert [m["device"] for m in rec.json["/carrier/event"].messages] == ["carrier", "chaser"]
