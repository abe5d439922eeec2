"""Fast start: help, argument errors and completion import nothing heavy.

``ffexp --help``, ``ffexp run --help``, ``-h`` and an argument error must not
import mujoco, OpenCV, matplotlib, scipy, filterpy or numpy (each costs hundreds of
milliseconds to seconds): the CLI modules import those inside the commands.
Checked in a fresh interpreter per command line (``sys.modules`` after the
command ran), never by timing.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
HEAVY = ("mujoco", "cv2", "matplotlib", "scipy", "filterpy", "foxglove", "pandas", "numpy")

_SCRIPT = """
import json, sys
wanted = json.loads(sys.argv[2])
sys.argv = ["ffexp", *json.loads(sys.argv[1])]
from ffexp.cli import main
code = 0
try:
    main()
except SystemExit as exc:
    code = exc.code
heavy = [m for m in wanted if m in sys.modules]
print("RESULT " + json.dumps({"code": code, "heavy": heavy}), file=sys.stderr)
"""


def run_cli(args: list[str], env: dict[str, str] | None = None) -> tuple[int, list[str], str]:
    done = subprocess.run(
        [sys.executable, "-c", _SCRIPT, json.dumps(args), json.dumps(HEAVY)],
        capture_output=True, text=True, cwd=ROOT, timeout=120,
        env={**os.environ, **(env or {})},
    )
    line = next(x for x in done.stderr.splitlines() if x.startswith("RESULT "))
    result = json.loads(line.removeprefix("RESULT "))
    return result["code"] or 0, result["heavy"], done.stdout + done.stderr


@pytest.mark.parametrize(
    ("args", "code"),
    [
        (["--help"], 0),
        (["-h"], 0),
        (["run", "--help"], 0),
        (["run", "-h"], 0),
        (["campaign", "-h"], 0),
        (["simulate", "contact-1dof", "-h"], 0),
        (["friction", "estimate", "-h"], 0),
        (["report", "-h"], 0),
        (["replay", "-h"], 0),
        (["diff", "-h"], 0),
        (["export", "-h"], 0),
        (["calibrate-camera", "-h"], 0),
        (["emulate", "-h"], 0),
        (["run"], 2),
        (["run", "p.toml", "--bogus"], 2),
        (["run", "p.toml", "--fri-port", "abc"], 2),
        (["nosuch"], 2),
        (["--version"], 0),
    ],
    ids=lambda a: " ".join(a) if isinstance(a, list) else str(a),
)
def test_help_and_argument_errors_import_nothing_heavy(args: list[str], code: int) -> None:
    got, heavy, output = run_cli(args)
    assert got == code, output
    assert heavy == [], f"ffexp {' '.join(args)} imported {heavy}"
    assert "Traceback" not in output


def test_usage_error_is_one_line_naming_the_option() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "ffexp", "run", "p.toml", "--fri-port", "abc"],
        capture_output=True, text=True, cwd=ROOT, timeout=120,
    )
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ffexp run: ")
    assert "--fri-port" in lines[0]


def test_shell_completion_is_offered() -> None:
    """The bash script, for the shell named on the command line: typer otherwise detects
    the shell from this process's ancestors (``/proc``), which a test run started from
    no shell (a service, ``setsid``, a CI runner) does not have."""
    no_detection = {"_TYPER_COMPLETE_TEST_DISABLE_SHELL_DETECTION": "1"}
    code, heavy, output = run_cli(["--show-completion", "bash"], env=no_detection)
    assert code == 0 and "_FFEXP_COMPLETE=complete_bash" in output, output
    env = {"_FFEXP_COMPLETE": "complete_bash", "COMP_WORDS": "ffexp camp", "COMP_CWORD": "1"}
    done = subprocess.run(
        [sys.executable, "-c", "from ffexp.cli import main; main()"],
        capture_output=True, text=True, cwd=ROOT, timeout=120, env={**os.environ, **env},
    )
    assert done.stdout.split() == ["campaign"], done.stdout + done.stderr
    assert heavy == []
