"""End to end over the wire: ``ffexp run --rig rigs/emulator.toml --camera URL`` against
``ffexp emulate --camera-port``: the camera tracker judges from the emulator's stream, and
its verdict equals the in-process run's truth verdict for the same seed."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from emulator_process import free_udp_ports, stop_emulator

from ffexp.analysis import metrics
from ffexp.experiment import run_file
from ffexp.recording import load

ROOT = Path(__file__).resolve().parents[1]
PROTOCOL = ROOT / "protocols" / "method1_case1.toml"
FFEXP = Path(sys.executable).parent / "ffexp"


def read_ready_line(emulator: subprocess.Popen[str], seen: list[str]) -> re.Match[str]:
    """Read the emulator's stderr up to its ready line (the ports it bound); whatever it
    says before (a library's warning on a busy machine) is kept in ``seen``."""
    assert emulator.stderr is not None
    for line in emulator.stderr:
        seen.append(line)
        found = READY.search(line)
        if found is not None:
            return found
    raise AssertionError("the emulator ended before its ready line:\n" + "".join(seen))


#: The emulator's ready line: its Net F/T port (it bound any free one) and camera port.
READY = re.compile(r"Net F/T on 0\.0\.0\.0:(\d+), camera on http://0\.0\.0\.0:(\d+)/stream\.mjpg")


@pytest.mark.slow
def test_camera_tracker_over_the_wire_judges_like_the_truth(tmp_path: Path) -> None:
    # the in-process run first: it compiles (or loads) the loop's and the world's kernels,
    # which a fresh clone would otherwise compile inside the wire run's first cycles,
    # seconds in which the lockstep emulator counts its misses
    local = metrics(load(run_file(PROTOCOL, [], out_dir=tmp_path / "sim").path))
    (fri_port,) = free_udp_ports(1)  # the run binds it: the emulator must know it first
    cal = tmp_path / "camera.toml"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    emulator = subprocess.Popen(
        [str(FFEXP), "emulate", "--remote", f"127.0.0.1:{fri_port}", "--pacing", "lockstep",
         "--netft-port", "0", "--seed", "1", "--camera-port", "0",
         "--camera-calibration", str(cal)],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env,
    )
    seen: list[str] = []
    try:
        found = read_ready_line(emulator, seen)
        netft_port, camera_port = found.group(1), found.group(2)
        url = f"http://127.0.0.1:{camera_port}/stream.mjpg"
        run = subprocess.run(
            [str(FFEXP), "run", str(PROTOCOL), "--rig", str(ROOT / "rigs/emulator.toml"),
             "--fri-port", str(fri_port), "--netft", f"127.0.0.1:{netft_port}",
             "--camera", url, "--rig-set", f"tracker.calibration='{cal}'",
             "--out", str(tmp_path / "fri")],
            capture_output=True, text=True, timeout=300, env=env,
        )
    finally:
        emu_err = "".join(seen) + stop_emulator(emulator)
    assert run.returncode == 0, run.stdout[-400:] + run.stderr + emu_err
    assert "Traceback" not in run.stderr + emu_err
    match = re.search(r"recording: (\S+)", run.stdout)
    assert match is not None, run.stdout
    wire = metrics(load(Path(match.group(1))))
    assert wire.verdict_source == "tracker" and wire.verdict_truth is None
    assert local.verdict_source == "truth"
    assert wire.verdict == local.verdict == "aligned"
    assert wire.contact_breaks == local.contact_breaks


@pytest.mark.parametrize(("args", "needle"), [
    (["--camera-port", "70000"], "--camera-port: 70000: a TCP port is -1..65535"),
    (["--camera-fps", "0"], "--camera-fps"),
])
def test_emulate_camera_options_are_checked(args: list[str], needle: str) -> None:
    from typer.testing import CliRunner

    from ffexp.cli import app

    result = CliRunner().invoke(app, ["emulate", "--remote", "127.0.0.1:5", *args])
    assert result.exit_code == 2
    assert needle in result.output and "Traceback" not in result.output
