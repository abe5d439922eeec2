"""What a newcomer meets: an output file that exists is never overwritten, a file of
another kind given as a scene is named as such, a bad option value is named by its
option (not by the scene file it went into), and a file that is no text or a directory
is one ``error:`` line, exit 2; a run that never got a measurement is a row of
``ffexp compare``, as ``ffexp analyze`` says it.

The recordings are written here with the Recorder (no simulation), as in
``tests/test_data_bad_input.py``; the one run is a robot that never answers (0.2 s).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from test_bad_input import check_one_line, expand  # the battery's own checks
from test_data_bad_input import write_run
from typer.testing import CliRunner

from drivers.description.scene import Scene
from ffexp.cli import app
from ffexp.cli.schema import KIND_NAMES
from ffexp.recording import Recorder
from ffexp.schemas import KINDS

ROOT = Path(__file__).resolve().parents[1]
runner = CliRunner()
KEPT = "kept: written before\n"
START_NS = 1_750_000_000 * 10**9


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    d = tmp_path_factory.mktemp("guard")
    rec = write_run(d / "rec.mcap", period_ms=5, span_s=0.1)
    sim = d / "sim.mcap"  # a simulator's run: its scene in its metadata
    with Recorder(sim) as r:
        r.metadata("run", {"protocol": "method2", "scene_json": Scene().model_dump_json()})
        r.log(START_NS, "INFO", "phase", "start")
    (d / "a_dir").mkdir()
    (d / "odd" / "campaign.json").mkdir(parents=True)
    (d / "binary.csv").write_bytes(bytes(range(128, 256)) * 4)
    (d / "points.csv").write_text("u,v,x,y\n0,0,0,0\n100,0,0.1,0\n0,100,0,0.1\n100,100,0.1,0.1\n")
    for name in ("kept.csv", "kept.mcap", "kept.avi", "kept.json", "kept.toml"):
        (d / name).write_text(KEPT)
    return {
        "tmp": str(d), "rec": str(rec), "sim": str(sim), "dir": str(d / "a_dir"),
        "odd_campaign": str(d / "odd"),
        "binary": str(d / "binary.csv"), "points": str(d / "points.csv"),
        "video": str(ROOT / "data/friction/sample.avi"),
        "rig": str(ROOT / "rigs/sim.toml"), "protocol": str(ROOT / "protocols/method2.toml"),
        "campaign": str(ROOT / "protocols/paper.toml"),
        "impact": str(ROOT / "protocols/hil_impact.toml"),
        **{f"kept_{ext}": str(d / f"kept.{ext}") for ext in ("csv", "mcap", "avi", "json",
                                                              "toml")},
    }

#: (command line, what its one error line names). None of them may touch a kept file.
CASES: list[tuple[str, list[str]]] = [
    # an output that exists: refused before any work, the file kept
    ("compare {rec} --csv {kept_csv}", ["--csv", "kept.csv", "exists", "never overwritten"]),
    ("recover {rec} -o {kept_mcap}", ["--output", "kept.mcap", "exists"]),
    ("replay {rec} --out {kept_mcap}", ["--out", "kept.mcap", "exists"]),
    ("calibrate-camera {points} {kept_toml}", ["kept.toml", "exists"]),
    ("friction synth --out {kept_avi} --duration 0.2", ["--out", "kept.avi", "exists"]),
    ("friction synth --out {tmp}/new.avi --duration 0.2 --truth {kept_json}",
     ["--truth", "kept.json", "exists"]),
    ("friction estimate {video} --px-per-m 1000 --record {kept_mcap}",
     ["--record", "kept.mcap", "exists"]),
    ("simulate contact-1dof --duration 0.1 --csv {kept_csv}", ["--csv", "kept.csv", "exists"]),
    # a rig given as a run protocol's scene file: named as a rig, not a scene's first error
    ("run {protocol} --set scene.file=\"../rigs/sim.toml\" --out {tmp}/out",
     ["sim.toml", "is a rig, not a scene"]),
    # a file that is no text, a directory where a file goes
    ("calibrate-camera {binary} {tmp}/cal.toml", ["binary.csv", "not a text file"]),
    ("friction estimate {dir} --px-per-m 1000", ["a_dir", "is a directory"]),
    ("friction estimate {video} --table-points {dir}", ["a_dir", "is a directory"]),
    # another kind of file where a scene goes: what it is, not its first table's error
    ("emulate --remote 127.0.0.1:49938 --set nosuch=1", ["--set/--scene-set", "nosuch",
                                                         "unknown key"]),
    ("emulate --remote 127.0.0.1:49938 --scene {rig}", ["--scene", "sim.toml", "is a rig, "
                                                        "not a scene", "--rig FILE"]),
    ("calibrate {rec} --fit target.mu --out {tmp}/c.toml --scene {protocol}",
     ["--scene", "method2.toml", "is a run protocol, not a scene"]),
    ("resimulate {rec} --out {tmp}/rs.mcap --scene {campaign}",
     ["--scene", "paper.toml", "is a campaign, not a scene"]),
    # the recording's own scene: named by the recording, not by a temporary file
    ("resimulate {sim} --out {tmp}/rs.mcap --scene-set target.mu=-1",
     ["sim.mcap (its recorded scene)", "target.mu"]),
    # an option's value: named by its option
    ("calibrate {rec} --fit target.mu=nan:0.01 --out {tmp}/c.toml",
     ["--fit", "target.mu=nan:0.01", "finite"]),
    ("hil-sweep {impact} --out {tmp}/hs --stiffness 5000,-5", ["--stiffness", "-5",
                                                               "contact.stiffness"]),
    ("hil-sweep {impact} --out {tmp}/hs --delays 0,101", ["--delays", "101",
                                                          "carrier.extra_delay_cycles"]),
    ("campaign {campaign} --resume {kept_csv}", ["--resume", "kept.csv", "not a directory"]),
    ("campaign {campaign} --resume {odd_campaign}", ["campaign.json", "cannot read: Is a "
                                                     "directory"]),
    ("report {tmp} -o {kept_mcap}", ["--out", "kept.mcap", "exists"]),
    # friction synth's settings: named by the option typed, and no video cut short is left
    ("friction synth --out {tmp}/new.avi --duration 0.2 --size 100x100",
     ["--block-m, --px-per-m, --size", "250.0 px"]),
    ("friction synth --out {tmp}/new.avi --duration 0.2 --size 32x720", ["--size", "64"]),
    ("friction synth --out {tmp}/new.avi --duration 0.2 --v0 -1", ["--v0", "greater than 0"]),
    ("friction synth --out {tmp}/new.avi --duration -1", ["--duration", "greater than 0"]),
    ("friction synth --out {tmp}/new.avi --duration 0.2 --start-px -5000,0",
     ["--start-px", "does not fit"]),
    ("friction synth --out {tmp}/new.avi --duration 0.2 --exposure-s 5",
     ["--exposure-s", "motion blur"]),
    ("friction synth --out {tmp}/new.avi --duration 0.2 --marker NOPE", ["--marker", "NOPE"]),
    ("friction estimate {video} --px-per-m 1000 --marker NOPE", ["--marker", "NOPE"]),
    ("friction estimate {video} --px-per-m 1000 --fps 0", ["--fps", "0", "> 0"]),
    ("friction estimate {video} --px-per-m 1000 --marker-id 3", ["--marker-id", "--marker"]),
    # a key the protocol does not have is --key's fault, not --range's
    ("limits {protocol} --key nosuch --range 0:1 --out {tmp}/lim", ["--key", "nosuch",
                                                                     "unknown key"]),
    ("limits {protocol} --key align.f_ref[2] --key scene.target.nosuch --range 0:1 "
     "--range 0:1 --out {tmp}/lim", ["--key", "scene.target.nosuch", "unknown key"]),
    ("limits {protocol} --key align.k_ri[9] --range 0:1 --out {tmp}/lim",
     ["--key", "align.k_ri[9]", "past the end"]),
    # ... and a sweep's: named by the key as typed, not by a sampled value of it
    ("sweep {protocol} --range align.k_ri[9]=0:1 --sample 2 --out {tmp}/lim",
     ["--range: align.k_ri[9]: index 9 past the end"]),
    ("sweep {protocol} --vary align.f_ref[2]=1,2 --range scene.target.nosuch=0:1 --sample 2 "
     "--out {tmp}/lim", ["--range: scene.target.nosuch: unknown key"]),
]


@pytest.mark.parametrize(("line", "needles"), CASES, ids=[c[0] for c in CASES])
def test_bad_input_is_one_line_exit_2_and_nothing_is_lost(
        files: dict[str, str], line: str, needles: list[str]) -> None:
    result = runner.invoke(app, expand(line, files))
    check_one_line(result.exit_code, result.stdout, result.stderr, needles)
    assert "recorded-scene.toml" not in result.stderr  # no temporary file named
    for ext in ("csv", "mcap", "avi", "json", "toml"):
        assert Path(files[f"kept_{ext}"]).read_text() == KEPT
    for made in ("new.avi", "cal.toml", "c.toml", "rs.mcap", "hs", "lim"):
        assert not (Path(files["tmp"]) / made).exists(), made


#: One case per command (the first of each), as a user's shell runs it.
SUBPROCESS = list({(" ".join(line.split()[:2]) if line.startswith("friction") else
                    line.split()[0]): (line, needles) for line, needles in reversed(CASES)
                   }.values())


@pytest.mark.slow
@pytest.mark.parametrize(("line", "needles"), SUBPROCESS, ids=[c[0] for c in SUBPROCESS])
def test_bad_input_in_a_subprocess(files: dict[str, str], line: str,
                                   needles: list[str]) -> None:
    done = subprocess.run([sys.executable, "-m", "ffexp", *expand(line, files)],
                          capture_output=True, text=True, timeout=300, cwd=files["tmp"])
    check_one_line(done.returncode, done.stdout, done.stderr, needles)
    assert Path(files["kept_mcap"]).read_text() == KEPT


def test_recover_beside_the_input_keeps_a_recovered_file_there(tmp_path: Path) -> None:
    rec = write_run(tmp_path / "run.mcap", period_ms=5, span_s=0.1)
    earlier = tmp_path / "run.recovered.mcap"
    earlier.write_text(KEPT)
    result = runner.invoke(app, ["recover", str(rec)])
    assert result.exit_code == 0, result.stderr
    assert earlier.read_text() == KEPT
    made = tmp_path / "run.recovered-1.mcap"
    assert f"into {made}" in result.stdout and made.read_bytes()[:8] == b"\x89MCAP0\r\n"


def test_compare_shows_a_run_that_never_got_a_measurement(tmp_path: Path) -> None:
    run = runner.invoke(app, [
        "run", str(ROOT / "protocols/method1_case1.toml"), "--driver", "fri",
        "--robot-ip", "127.0.0.1", "--fri-port", "0", "--ft", "mock",
        "--rig-set", "robot.connect_timeout_s=0.2", "--out", str(tmp_path)])
    assert run.exit_code == 3, run.stdout + run.stderr
    (silent,) = tmp_path.glob("*.mcap")
    result = runner.invoke(app, ["compare", str(silent), "--json"])
    assert result.exit_code == 0, result.stderr
    row = json.loads(result.stdout)
    assert row["file"] == str(silent) and row["protocol"] == "method1_case1"
    assert row["outcome"].startswith("no measurement received")
    assert row["trial_valid"] is False and row["contact_breaks"] is None
    table = runner.invoke(app, ["compare", str(silent), "--wide", "--csv",
                                str(tmp_path / "t.csv")])
    assert table.exit_code == 0 and "no measurement" in " ".join(table.stdout.split())
    assert "no measurement received" in (tmp_path / "t.csv").read_text()


def test_schema_help_names_every_kind() -> None:
    assert KIND_NAMES == tuple(KINDS)
    result = runner.invoke(app, ["schema", "-h"])
    assert "hil-impact" in " ".join(result.stdout.split())


def test_a_scene_made_valid_by_its_overrides_passes_the_kind_check(
        files: dict[str, str]) -> None:
    """The kind check reads the scene file alone; a scene that only its --scene-set
    makes valid is not stopped there (the replay goes on to the recording)."""
    scene = Path(files["tmp"]) / "negative_mu.toml"
    scene.write_text("[target]\nmu = -1.0\n")
    line = ["resimulate", files["rec"], "--out", str(Path(files["tmp"]) / "o.mcap"),
            "--scene", str(scene)]
    alone = runner.invoke(app, line)
    check_one_line(alone.exit_code, alone.stdout, alone.stderr, ["negative_mu.toml",
                                                                 "target.mu"])
    fixed = runner.invoke(app, [*line, "--scene-set", "target.mu=0.005"])
    check_one_line(fixed.exit_code, fixed.stdout, fixed.stderr, ["rec.mcap", "/robot/command"])
