"""The command lines: ``ffexp emulate`` and ``ffexp run --driver fri``.

One test runs a paper protocol through the real CLI: ``ffexp emulate
--pacing lockstep`` and ``ffexp run --driver fri`` as two processes on
loopback, and compares the outcome with the in-process run. Over FRI there
is no ground truth, so the in-process run judges alignment from settings as
well (``alignment.source=settings``). The other tests check that bad input
gives one error line and a non-zero exit.
"""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from emulator_process import free_udp_port, free_udp_ports, stop_emulator
from typer.testing import CliRunner

from ffexp.analysis import metrics
from ffexp.cli import app
from ffexp.experiment import run_file
from ffexp.recording import load

ROOT = Path(__file__).resolve().parent.parent
PROTOCOL = ROOT / "protocols" / "method3_impedance.toml"
#: A paper protocol that ends aligned (Method III now runs its 40 s and keeps breaking).
ALIGNING = ROOT / "protocols" / "method1_case1.toml"
FFEXP = Path(sys.executable).parent / "ffexp"
runner = CliRunner()


def one_error_line(result: object, *needles: str) -> None:
    out = result.stdout + result.stderr  # type: ignore[attr-defined]
    assert "Traceback" not in out
    lines = result.stderr.strip().splitlines()  # type: ignore[attr-defined]
    assert len(lines) == 1, lines
    assert lines[0].startswith("error: ")
    for n in needles:
        assert n in lines[0], lines[0]


BUILTIN = "<built-in fri rig>"


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["--driver", "fri"], [BUILTIN, "robot.robot_ip", "required"]),
        (["--driver", "fri", "--robot-ip", "10.0.0"], ["robot.robot_ip: 10.0.0", "IPv4"]),
        (["--driver", "fri", "--robot-ip", "no such.host"], ["robot.robot_ip: no such.host"]),
        (["--driver", "fri", "--robot-ip", "127.0.0.1", "--ft", "sim"], ["ft.type", "emulator"]),
        (["--driver", "fri", "--robot-ip", "127.0.0.1", "--ft", "magic"], ["ft", "magic"]),
        (["--driver", "fri", "--robot-ip", "127.0.0.1", "--fri-port", "70000"],
         ["robot.port", "65535"]),
        (["--driver", "fri", "--robot-ip", "127.0.0.1", "--fri-port", "0",
          "--netft", "127.0.0.1:x"], ["ft.port", "integer"]),
        (["--ft", "netft"], ["<built-in sim rig>", "ft.host", "fri1"]),
        (["--rig", str(ROOT / "rigs/emulator.toml"), "--rig-set", "robot.robot_ip='1.2.3'"],
         ["rigs/emulator.toml: robot.robot_ip: 1.2.3"]),
    ],
)
def test_run_bad_link_options(args: list[str], needles: list[str], tmp_path: Path) -> None:
    result = runner.invoke(app, ["run", str(PROTOCOL), "--out", str(tmp_path), *args])
    assert result.exit_code == 2
    one_error_line(result, *needles)
    assert not list(tmp_path.iterdir())  # nothing recorded


def test_run_port_in_use_is_one_line(tmp_path: Path) -> None:
    busy = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        busy.bind(("0.0.0.0", 0))
        port = busy.getsockname()[1]
        result = runner.invoke(app, ["run", str(PROTOCOL), "--out", str(tmp_path), "--driver",
                                     "fri", "--robot-ip", "127.0.0.1", "--fri-port", str(port)])
    finally:
        busy.close()
    assert result.exit_code == 2
    one_error_line(result, f"robot.port: 0.0.0.0:{port}", "cannot bind")
    assert not list(tmp_path.iterdir())  # nothing recorded


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["--remote", "127.0.0.1"], ["--remote: 127.0.0.1: expected HOST:PORT"]),
        (["--remote", "1.2.3:5"], ["--remote: 1.2.3: not a valid IPv4"]),
        (["--remote", "127.0.0.1:0"], ["--remote: 127.0.0.1:0: port 0"]),
        (["--remote", "127.0.0.1:5", "--pacing", "fast"], ["--pacing"]),
        (["--remote", "127.0.0.1:5", "--loss", "120"], ["--loss"]),
        (["--remote", "127.0.0.1:5", "--cycle-ms", "0"], ["--cycle-ms"]),
        (["--remote", "127.0.0.1:5", "--scene", "/nonexistent.toml"], ["/nonexistent.toml"]),
    ],
)
def test_emulate_bad_options(args: list[str], needles: list[str]) -> None:
    result = runner.invoke(app, ["emulate", *args])
    assert result.exit_code == 2
    one_error_line(result, *needles)


def test_emulate_port_in_use_is_one_line() -> None:
    busy = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        busy.bind(("0.0.0.0", 0))
        port = busy.getsockname()[1]
        result = runner.invoke(
            app, ["emulate", "--remote", "127.0.0.1:5", "--netft-port", str(port)]
        )
    finally:
        busy.close()
    assert result.exit_code == 2
    one_error_line(result, f"--netft-port: 0.0.0.0:{port}: cannot bind")


def test_emulate_stops_on_sigterm_while_waiting_for_the_remote() -> None:
    """Lockstep with nobody answering: SIGTERM ends it at once, counters printed, exit 0."""
    emulator = subprocess.Popen(
        [str(FFEXP), "emulate", "--remote", f"127.0.0.1:{free_udp_port()}", "--pacing",
         "lockstep", "--netft-port", "-1", "--timeout-ms", "50"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    try:
        assert emulator.stderr is not None
        first = emulator.stderr.readline()  # printed once the KRC's socket is bound
        assert first.startswith("ffexp emulate: KRC on 0.0.0.0:"), first
        emulator.send_signal(signal.SIGTERM)
        _out, err = emulator.communicate(timeout=10)
    finally:
        if emulator.poll() is None:
            emulator.kill()
            emulator.communicate()
    assert emulator.returncode == 0, err
    assert "Traceback" not in err
    # it never got an answer: the first packet was re-sent, the world never stepped
    assert re.search(r"^ffexp emulate: cycles 0, sent 1, answered 0, ", err, re.M), err


@pytest.mark.slow
def test_a_paper_protocol_over_the_cli_matches_the_in_process_run(tmp_path: Path) -> None:
    seed = load_seed()
    fri_port, netft_port = free_udp_ports(2)
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    emulator = subprocess.Popen(
        [str(FFEXP), "emulate", "--remote", f"127.0.0.1:{fri_port}", "--pacing", "lockstep",
         "--netft-port", str(netft_port), "--seed", str(seed),
         "--scene", str(ROOT / "data" / "scenes" / "paper.toml")],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
    )
    try:
        run = subprocess.run(
            [str(FFEXP), "run", str(ALIGNING), "--rig", str(ROOT / "rigs/emulator.toml"),
             "--fri-port", str(fri_port), "--netft", f"127.0.0.1:{netft_port}",
             "--set", "alignment.source=settings",  # the same judge as the local run below
             "--out", str(tmp_path / "fri")],
            capture_output=True, text=True, timeout=240, env=env,
        )
    finally:
        emu_err = stop_emulator(emulator)
    assert run.returncode == 0, run.stdout[:400] + run.stderr + emu_err
    assert emulator.returncode == 0, emu_err
    assert "Traceback" not in run.stderr + emu_err
    assert f"fri: listening on 0.0.0.0:{fri_port}" in run.stderr
    assert "ffexp emulate: cycles" in emu_err
    match = re.search(r"recording: (\S+)", run.stdout)
    assert match is not None, run.stdout
    over_udp = metrics(load(Path(match.group(1))))
    assert "DONE (aligned)" in run.stdout

    local = run_file(ALIGNING, ["alignment.source=settings"], out_dir=tmp_path / "sim")
    assert local.outcome.aligned
    assert local.outcome.breaks == over_udp.contact_breaks


def load_seed() -> int:
    from ffexp.protocol import load_run_protocol

    return load_run_protocol(ALIGNING).seed
