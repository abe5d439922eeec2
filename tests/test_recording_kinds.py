"""A recording of another kind than a run's (an impact's, ``ffexp hil``; a friction
track, ``ffexp friction estimate --record``) given to a command that reads a run's is
named as such, one ``error:`` line and exit 2, instead of the first topic or metadata
it lacks ("no topic /estimator/state", "give --scene"); ``ffexp diff`` of two files
without a numeric topic in common is bad input, not "within tolerance on 0 topics".
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from test_bad_input import check_one_line, expand  # the battery's own checks
from test_data_bad_input import write_run
from typer.testing import CliRunner

from ffexp.cli import app
from ffexp.hil.record import HIL_METADATA
from ffexp.recording import load
from ffexp.recording.kind import OTHER_KINDS, not_a_run

ROOT = Path(__file__).resolve().parents[1]
runner = CliRunner()


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    d = tmp_path_factory.mktemp("kinds")
    track = d / "track.mcap"
    made = runner.invoke(app, ["friction", "estimate", str(ROOT / "data/friction/sample.avi"),
                               "--px-per-m", "360", "--record", str(track)])
    assert made.exit_code == 0, made.stderr
    impact = runner.invoke(app, ["hil", str(ROOT / "protocols/hil_impact.toml"),
                                 "--out", str(d)])
    assert impact.exit_code == 0, impact.stderr
    return {"tmp": str(d), "track": str(track), "impact": str(d / "hil_impact.mcap"),
            "run": str(write_run(d / "run.mcap", period_ms=5, span_s=0.1))}


TRACK = ["track.mcap", "is a friction track", "not a run recording"]
IMPACT = ["hil_impact.mcap", "is an impact recording", "not a run recording"]
CASES: list[tuple[str, list[str]]] = [
    ("analyze {track}", TRACK),
    ("compare {track} {run}", TRACK),
    ("compare {impact}", IMPACT),
    ("replay {track} --out {tmp}/o.mcap", TRACK),
    ("replay {impact} --out {tmp}/o.mcap", IMPACT),
    ("resimulate {impact} --out {tmp}/o.mcap", IMPACT),
    ("calibrate {track} --fit target.mu --out {tmp}/o.toml", TRACK),
    ("calibrate {run} --fit target.mu --out {tmp}/o.toml --holdout {impact}", IMPACT),
    ("diff {track} {run}", ["track.mcap", "run.mcap", "no numeric topic in both"]),
]


@pytest.mark.parametrize(("line", "needles"), CASES, ids=[c[0] for c in CASES])
def test_another_kind_of_recording_is_named(files: dict[str, str], line: str,
                                            needles: list[str]) -> None:
    result = runner.invoke(app, expand(line, files))
    check_one_line(result.exit_code, result.stdout, result.stderr, needles)
    assert not any(Path(files["tmp"]).glob("o.*"))


@pytest.mark.parametrize("line", ["compare {impact}", "replay {track} --out {tmp}/o.mcap"])
def test_another_kind_of_recording_in_a_subprocess(files: dict[str, str], line: str) -> None:
    done = subprocess.run([sys.executable, "-m", "ffexp", *expand(line, files)],
                          capture_output=True, text=True, timeout=120, cwd=files["tmp"])
    check_one_line(done.returncode, done.stdout, done.stderr, ["not a run recording"])


def test_the_kinds_are_the_metadata_their_commands_write(files: dict[str, str]) -> None:
    track, impact, run = (load(files[k], []) for k in ("track", "impact", "run"))
    assert set(OTHER_KINDS) == {HIL_METADATA, *track.metadata}
    assert HIL_METADATA in impact.metadata
    assert not_a_run(run.metadata) is None and not_a_run({}) is None
    # an impact's own reader still reads it
    result = runner.invoke(app, ["analyze", files["impact"], "--json"])
    assert result.exit_code == 0 and '"restitution"' in result.stdout
