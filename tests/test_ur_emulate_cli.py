"""``ffexp emulate --robot ur5e`` serves the simulated UR5e over RTDE to ``ffexp run`` with
rigs/ur5e-emulator.toml, in lockstep; a SIGTERM ends it with its counters; a bad --robot is
one line and exit 2."""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from test_rtde_ur_rtde import free_loopback_host

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}


def _line_with(stream: object, text: str, timeout_s: float) -> str:
    """The first line of ``stream`` containing ``text`` (empty: none within the deadline)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if select.select([stream], [], [], 0.5)[0]:
            line = stream.readline()  # type: ignore[attr-defined]
            if not line:
                return ""
            if text in line:
                return str(line)
    return ""


def _emulator(host: str) -> subprocess.Popen[str]:
    """``ffexp emulate --robot ur5e`` in lockstep on ``host:30004`` (its log on stderr)."""
    return subprocess.Popen([sys.executable, "-m", "ffexp", "emulate", "--robot", "ur5e",
                             "--listen", f"{host}:30004", "--pacing", "lockstep", "--seed", "1"],
                            cwd=ROOT, env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True)


@pytest.mark.slow
def test_ffexp_run_drives_the_emulated_ur5e_over_rtde(tmp_path: Path) -> None:
    host = free_loopback_host()
    emu = _emulator(host)
    try:
        assert f"UR5e controller (RTDE) on {host}:30004" in _line_with(emu.stderr, "UR5e", 60)
        run = subprocess.run([sys.executable, "-m", "ffexp", "run",
                              str(ROOT / "protocols/method1_case1.toml"),
                              "--rig", str(ROOT / "rigs/ur5e-emulator.toml"),
                              "--rig-set", f"robot.robot_ip={host}",
                              "--set", "run.timeout_s=1.0", "--out", str(tmp_path)],
                             cwd=ROOT, env=ENV, capture_output=True, text=True, timeout=300)
    finally:
        emu.send_signal(signal.SIGTERM)
        summary = _line_with(emu.stderr, "UR5e over RTDE", 60)
        emu.wait(60)
    assert run.returncode == 4, run.stdout + run.stderr  # the 1 s timeout, not aligned
    assert len(list(tmp_path.glob("*.mcap"))) == 1
    assert emu.returncode == 0 and "cycles" in summary


def test_a_robot_ffexp_emulate_does_not_know_is_one_line_and_exit_2() -> None:
    done = subprocess.run([sys.executable, "-m", "ffexp", "emulate", "--robot", "warp"],
                          cwd=ROOT, env=ENV, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    from drivers.emulate.robots import robot_names

    assert {"lwr4", "ur5e"} <= set(robot_names())
    assert done.stderr.strip().splitlines() == [
        f"error: --robot: warp: choose one of {', '.join(robot_names())}"]


@pytest.mark.slow
def test_a_campaign_over_rtde_against_one_emulator_equals_the_same_campaign_in_process(
        tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from ffexp.cli import app

    camp = tmp_path / "two.toml"
    runs = "".join(f'\n[[runs]]\nprotocol = "{ROOT / "protocols" / name}.toml"\n'
                   for name in ("method1_case1", "method2"))
    camp.write_text(f'name = "two"\n{runs}')
    common = ["campaign", str(camp), "--set", "run.timeout_s=4.2", "--no-figures"]
    runner = CliRunner()
    inproc = runner.invoke(app, [*common, "--rig", str(ROOT / "rigs/ur5e-sim.toml"),
                                 "--rig-set", "robot.truth=false", "--out", str(tmp_path / "in")])
    assert inproc.exit_code == 0, inproc.output
    host = free_loopback_host()
    emu = _emulator(host)
    try:
        assert "UR5e controller" in _line_with(emu.stderr, "UR5e", 60)
        wire = runner.invoke(app, [*common, "--rig", str(ROOT / "rigs/ur5e-emulator.toml"),
                                   "--rig-set", f"robot.robot_ip={host}",
                                   "--out", str(tmp_path / "wire")])
    finally:
        emu.send_signal(signal.SIGTERM)
        summary = _line_with(emu.stderr, "UR5e over RTDE", 60)
        emu.wait(60)
    assert wire.exit_code == 0, wire.output
    assert "in 2 sessions" in summary  # one emulator served both runs
    for name in ("method1_case1", "method2"):
        (a,) = (tmp_path / "in").glob(f"*/{name}-*.mcap")
        (b,) = (tmp_path / "wire").glob(f"*/{name}-*.mcap")
        same = runner.invoke(app, ["diff", str(a), str(b), "--rtol", "0", "--atol", "0"])
        # the second run started from the emulator's start, as in-process: equal bit for bit
        assert same.exit_code == 0, same.output
