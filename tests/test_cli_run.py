"""``ffexp run`` and ``ffexp campaign`` through the CLI."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from ffexp.cli import app
from ffexp.recording import load

ROOT = Path(__file__).resolve().parents[1]
runner = CliRunner()


@pytest.mark.slow
def test_campaign_prints_the_papers_table_and_writes_figures(tmp_path: Path) -> None:
    result = runner.invoke(
        app,
        ["campaign", str(ROOT / "protocols/paper.toml"), "--set", "run.timeout_s=1.5",
         "--out", str(tmp_path)],
    )
    assert result.exit_code == 0, result.stderr
    assert "the paper (Table res_par" in result.stdout and "agree" in result.stdout
    (camp,) = tmp_path.glob("paper-*")
    for name in ("method1_case1", "method1_case2", "method2", "method2_f08",
                 "method3_impedance"):
        assert name in result.stdout
        (rec,) = camp.glob(f"{name}-[!f]*.mcap")  # method2-..., not method2_f08-...
        for kind in ("wrench", "applied"):
            assert (camp / "figures" / f"{rec.stem}_{kind}.png").read_bytes()[:4] == b"\x89PNG"
            assert (camp / "figures" / f"{rec.stem}_{kind}.svg").is_file()
    assert (camp / "figures/paper_all_wrench.png").read_bytes()[:4] == b"\x89PNG"
    manifest = json.loads((camp / "campaign.json").read_text())
    assert [r["protocol"] for r in manifest["runs"]] == [
        "method1_case1", "method1_case2", "method2", "method2_f08", "method3_impedance"]


@pytest.mark.parametrize(
    ("content", "field"),
    [
        ('name = "x"\nmethod = "force_ri"\ncolour = 1\n', "colour"),
        ('name = "x"\nmethod = "telepathy"\n', "method"),
        ('name = "x"\nmethod = "force"\n[align]\nk_ri = [0, 1, 0, 0, 0, 0]\n', "k_ri"),
        ('name = "x"\n[align]\nmethod = "force"\nkp = "high"\n', "align.kp"),
        ('name = "x"\n[align]\nmethod = "admittance"\nmass = [1, 0, 1, 1, 1, 1]\n', "mass"),
        ('name = "x"\nmethod = "force_ri"\n[scene]\nfile = "nope.toml"\n', "nope.toml"),
        ('name = "x"\n[paper]\noutcome = "aligend"\n', "paper"),  # not the paper's words
    ],
)
def test_bad_run_protocol_one_line_exit_2(tmp_path: Path, content: str, field: str) -> None:
    path = tmp_path / "p.toml"
    path.write_text(content)
    result = runner.invoke(app, ["run", str(path), "--out", str(tmp_path / "runs")])
    assert result.exit_code == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and field in lines[0], result.stderr
    assert not (tmp_path / "runs").exists() or not list((tmp_path / "runs").glob("*.mcap"))


def test_bad_campaign_entry(tmp_path: Path) -> None:
    camp = tmp_path / "c.toml"
    camp.write_text('name = "c"\n[[runs]]\nprotocol = "missing.toml"\n')
    result = runner.invoke(app, ["campaign", str(camp)])
    assert result.exit_code == 2
    assert "runs.0.protocol" in result.stderr and "missing.toml" in result.stderr


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_stops_safely_and_keeps_the_recording(tmp_path: Path, sig: int) -> None:
    proc = subprocess.Popen(
        [sys.executable, "-c", "from ffexp.cli import main; main()", "run",
         str(ROOT / "protocols/method3_impedance.toml"), "--out", str(tmp_path),
         # a slow approach: the run is still going when the signal comes, however fast
         "--set", "approach.speed_mps=0.0005", "--set", "run.timeout_s=600"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    deadline = time.monotonic() + 120
    while not list(tmp_path.glob("*.mcap")):  # the run has started recording
        assert time.monotonic() < deadline and proc.poll() is None
        time.sleep(0.1)  # real-time
    time.sleep(1.0)  # real-time: let it run a little
    proc.send_signal(sig)
    _out, err = proc.communicate(timeout=120)
    assert proc.returncode == 128 + sig, err
    (path,) = tmp_path.glob("*.mcap")
    rec = load(path)
    assert rec.complete  # finished properly, not just flushed
    phases = rec.json["/runner/phase"].messages
    assert phases[-1]["phase"] == "ABORT" and "stop requested" in phases[-1]["reason"]
    cmd = rec.topic("/robot/command")
    assert (cmd["add_tcp_ft"][-1] == 0.0).all()
    assert "Traceback" not in err


def test_a_rig_file_selects_the_mock_robot(tmp_path: Path) -> None:
    result = runner.invoke(
        app, ["run", str(ROOT / "protocols/method1_case1.toml"), "--rig",
              str(ROOT / "rigs/mock.toml"), "--set", "run.timeout_s=1", "--out", str(tmp_path)],
    )
    assert result.exit_code == 4, result.stderr  # DONE at the timeout, not aligned
    (path,) = tmp_path.glob("*.mcap")
    rec = load(path)
    assert rec.metadata["run"]["rig"].endswith("rigs/mock.toml")
    assert rec.metadata["run"]["run_name"] == path.stem
    assert rec.metadata["run"]["source_revision"]
    assert "/robot/measurement" not in rec.topics  # no FRI back-end, no FRI packets
    intent = rec.topic("/control/command")
    assert intent["given"][0] == 0 and intent["given"][-1] == 1  # CONNECT holds, then commands
    phases = [m["phase"] for m in rec.json["/runner/phase"].messages]
    assert phases == ["CONNECT", "APPROACH", "DONE"]
    assert rec.json["/runner/phase"].messages[-1]["stop_reason"] == "timeout"


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["--rig", "nope.toml"], ["nope.toml", "not found"]),
        (["--rig", "RIG", "--rig-set", "robot.cycles=-1"], ["mock.toml", "robot.cycles"]),
        (["--rig", "RIG", "--rig-set", "robot.type=warp"], ["mock.toml", "robot"]),
        (["--driver", "warp"], ["--driver", "warp"]),
        (["--driver", "fri"], ["robot.robot_ip", "required"]),
    ],
)
def test_bad_rig_is_one_line_exit_2(tmp_path: Path, args: list[str], needles: list[str]) -> None:
    args = [str(ROOT / "rigs/mock.toml") if a == "RIG" else a for a in args]
    result = runner.invoke(
        app, ["run", str(ROOT / "protocols/method2.toml"), "--out", str(tmp_path), *args]
    )
    assert result.exit_code == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and all(n in lines[0] for n in needles), result.stderr
    assert not list(tmp_path.glob("*.mcap"))
