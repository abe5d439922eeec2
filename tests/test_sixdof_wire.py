"""A 6-DOF run on the zero-g target over the wire, in lockstep, equals the same run in
process, every numeric topic bit for bit: over FRI against ``ffexp emulate`` (the KRC's
own F/T estimate, at wire precision) and over RTDE against ``ffexp emulate --robot
ur5e`` (the UR5e in the zero-g scene in place of the LWR4+, as in process).

Over the wire no ground truth crosses: both sides are judged alike (``task.source =
"tracker"`` with no tracker: unverified), so only the physics and the loop compare.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from test_rtde_ur_rtde import free_loopback_host
from test_ur_emulate_cli import _line_with
from typer.testing import CliRunner

from ffexp.cli import app

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
PROTOCOL = str(ROOT / "protocols" / "sixdof_method1.toml")
ZERO_G = str(ROOT / "data" / "scenes" / "zero-g.toml")
#: Long enough for the tool to reach the target and push it (first contact near 3.3 s).
RUN = ["--set", "run.timeout_s=5.0", "--set", 'task.source="tracker"']


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _equal(here: Path, wire: Path, topics: tuple[str, ...]) -> None:
    (a,) = here.glob("*.mcap")
    (b,) = wire.glob("*.mcap")
    args = ["diff", str(a), str(b), "--rtol", "0", "--atol", "0"]
    for topic in topics:
        args += ["--topic", topic]
    same = CliRunner().invoke(app, args)
    assert same.exit_code == 0, same.output
    assert f"on {len(topics)} topics" in same.output


@pytest.mark.slow
def test_a_6dof_run_over_fri_equals_the_in_process_run(tmp_path: Path) -> None:
    # the in-process run first: it loads (on a fresh clone, compiles) the loop's compiled
    # kernels, which would otherwise stall the wire run's first cycles past the link's 1 s
    here = CliRunner().invoke(app, [
        "run", PROTOCOL, "--rig-set", "robot.wire_precision=true", "--ft", "fri-estimate",
        *RUN, "--out", str(tmp_path / "here")])
    assert here.exit_code == 4, here.output
    port = _free_udp_port()
    emu = subprocess.Popen(
        [sys.executable, "-m", "ffexp", "emulate", "--remote", f"127.0.0.1:{port}",
         "--pacing", "lockstep", "--seed", "1", "--scene", ZERO_G, "--port", "0",
         "--netft-port", "0", "--duration", "120"],
        cwd=ROOT, env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        assert "KRC" in _line_with(emu.stderr, "KRC", 60)
        wire = CliRunner().invoke(app, [
            "run", PROTOCOL, "--driver", "fri", "--robot-ip", "127.0.0.1", "--fri-port",
            str(port), "--ft", "fri-estimate", *RUN, "--out", str(tmp_path / "wire")])
    finally:
        emu.send_signal(signal.SIGTERM)
        emu.wait(60)
    assert wire.exit_code == 4, wire.output  # DONE at the timeout, unverified
    _equal(tmp_path / "here", tmp_path / "wire",
           ("/robot/state", "/estimator/state", "/control/command", "/control/terms"))


@pytest.mark.slow
def test_a_6dof_run_over_rtde_equals_the_in_process_run(tmp_path: Path) -> None:
    here = CliRunner().invoke(app, [  # first, as above
        "run", PROTOCOL, "--rig", str(ROOT / "rigs" / "ur5e-sim.toml"),
        "--rig-set", "robot.truth=false", "--rig-set", f'robot.scene_file="{ZERO_G}"',
        *RUN, "--out", str(tmp_path / "here")])
    assert here.exit_code == 4, here.output
    host = free_loopback_host()
    emu = subprocess.Popen(
        [sys.executable, "-m", "ffexp", "emulate", "--robot", "ur5e", "--listen",
         f"{host}:30004", "--pacing", "lockstep", "--seed", "1", "--scene", ZERO_G],
        cwd=ROOT, env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        assert "UR5e controller" in _line_with(emu.stderr, "UR5e", 60)
        wire = CliRunner().invoke(app, [
            "run", PROTOCOL, "--rig", str(ROOT / "rigs" / "ur5e-emulator.toml"),
            "--rig-set", f"robot.robot_ip={host}", *RUN, "--out", str(tmp_path / "wire")])
    finally:
        emu.send_signal(signal.SIGTERM)
        emu.wait(60)
    assert wire.exit_code == 4, wire.output
    _equal(tmp_path / "here", tmp_path / "wire",
           ("/robot/state", "/robot/ur", "/ft/raw", "/estimator/state", "/control/command",
            "/control/terms"))
