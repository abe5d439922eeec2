"""``ffexp emulate --duration`` ends the emulator even when no client ever comes: without
one no simulated time passes (lockstep waits for answers, a UR steps only while a client
streams), so the duration is then counted in wall time."""

from __future__ import annotations

import subprocess
import sys

import pytest

DEADLINE_S = 120.0  # a deadline for a hang, not a measure of speed


@pytest.mark.parametrize(("args", "summary"), [
    (["--remote", "127.0.0.38:49938", "--pacing", "lockstep", "--netft-port", "-1"],
     "answered 0"),
    (["--robot", "ur5e", "--listen", "127.0.0.38:30004"], "0 cycles in 0 sessions"),
])
def test_an_emulator_no_client_drives_ends_at_its_duration(args: list[str],
                                                           summary: str) -> None:
    done = subprocess.run([sys.executable, "-m", "ffexp", "emulate", *args, "--duration",
                           "0.3"], capture_output=True, text=True, timeout=DEADLINE_S)
    assert done.returncode == 0, done.stderr
    assert summary in done.stderr.splitlines()[-1]
