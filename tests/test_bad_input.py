"""The bad-input battery: every command, every kind of input a user gets wrong.

Each case runs through typer's CliRunner (a few also as subprocesses) and
must end with the documented exit code (2: bad input), no traceback, and
exactly one line on stderr, ``error: ...``, naming the culprit: the file,
the field, the address or the option. None of these runs an experiment: the
errors come before any device opens (a recording for the cases that need one
comes from one short dry run on the mock rig).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.writer import Writer
from typer.testing import CliRunner

from ffexp.cli import app

ROOT = Path(__file__).resolve().parents[1]
runner = CliRunner()
P = str(ROOT / "protocols/method2.toml")
CAMP = str(ROOT / "protocols/paper.toml")
SWEEP = str(ROOT / "protocols/sec3_stiffness.toml")
SCENE = str(ROOT / "data/scenes/paper.toml")
VIDEO = str(ROOT / "data/friction/sample.avi")
MOCK = str(ROOT / "rigs/mock.toml")
HIL = str(ROOT / "protocols/hil_impact.toml")


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """Bad (and one good) input files, by placeholder name."""
    d = tmp_path_factory.mktemp("bad")
    out: dict[str, Path] = {
        "dir": d / "a_dir",
        "file": d / "a_file.txt",
        "empty": d / "empty.mcap",
        "text": d / "text.mcap",
        "magic": d / "magic.mcap",
        "foreign": d / "foreign.mcap",
        "badtoml": d / "bad.toml",
        "colour": d / "colour.toml",
        "kp": d / "kp.toml",
        "scene": d / "scene.toml",
        "camp_missing": d / "camp_missing.toml",
        "camp_empty": d / "camp_empty.toml",
        "camp_badentry": d / "camp_badentry.toml",
        "sweep_empty": d / "sweep_empty.toml",
        "sweep_field": d / "sweep_field.toml",
        "emptydir": d / "emptydir",
        "badjson_dir": d / "badjson",
        "listjson_dir": d / "listjson",
        "points": d / "points.json",
        "nodir": d / "no/such/dir/out.csv",
        "pts_few": d / "pts_few.csv",
        "pts_text": d / "pts_text.csv",
        "pts_cols": d / "pts_cols.csv",
        "pts_line": d / "pts_line.csv",
    }
    out["dir"].mkdir()
    out["emptydir"].mkdir()
    out["file"].write_text("x\n")
    out["pts_few"].write_text("u,v,x,y\n0,0,0,0\n100,0,0.1,0\n0,100,0,0.1\n")
    out["pts_text"].write_text("u,v,x,y\n0,0,0,0\n100,zero,0.1,0\n")
    out["pts_cols"].write_text("0,0,0,0\n100,0,0.1\n")
    # four points on one line: no homography
    out["pts_line"].write_text("".join(f"{i * 100},0,{i * 0.1},0\n" for i in range(4)))
    out["empty"].write_bytes(b"")
    out["text"].write_text("not a recording\n")
    out["magic"].write_bytes(b"\x89MCAP0\r\nxy")
    with out["foreign"].open("wb") as fh:
        w = Writer(fh)
        w.start()
        cid = w.register_channel("/other", "json", w.register_schema("x", "jsonschema", b"{}"))
        w.add_message(cid, 1, b"{}", 1)
        w.finish()
    out["badtoml"].write_text("name = \n")
    out["colour"].write_text('name = "x"\ncolour = 1\n')
    out["kp"].write_text('name = "x"\n[align]\nmethod = "force"\nkp = "high"\n')
    out["scene"].write_text('name = "x"\n[scene]\nfile = "nope_scene.toml"\n')
    out["camp_missing"].write_text('name = "c"\n[[runs]]\nprotocol = "missing.toml"\n')
    out["camp_empty"].write_text('name = "c"\nruns = []\n')
    out["camp_badentry"].write_text(f'name = "c"\n[[runs]]\nprotocol = "{out["kp"].name}"\n')
    out["sweep_empty"].write_text('name = "s"\n[sweep]\nparameter = "k_ri"\nvalues = []\n')
    out["sweep_field"].write_text('name = "s"\n[sweep]\nparameter = "colour"\nvalues = [1]\n')
    out["badjson_dir"].mkdir()
    (out["badjson_dir"] / "campaign.json").write_text("{not json")
    out["listjson_dir"].mkdir()
    (out["listjson_dir"] / "campaign.json").write_text("[1, 2]")
    out["points"].write_text('{"image_px": [[0, 0]], "table_m": [[0, 0]]}')
    # one real recording: a dry run on the mock rig (no physics, a fraction of a second)
    runs = d / "runs"
    done = runner.invoke(app, ["run", P, "--rig", MOCK, "--set", "run.timeout_s=0.2",
                               "--out", str(runs)])
    assert done.exit_code == 4, done.stderr
    (out["rec"],) = runs.glob("*.mcap")
    return {k: str(v) for k, v in out.items()} | {"tmp": str(d)}


# (command line with {placeholders}, the words the one error line must contain)
CASES: list[tuple[str, list[str]]] = [
    # calibrate-camera
    ("calibrate-camera {tmp}/nope.csv {tmp}/cal.toml", ["nope.csv", "cannot read"]),
    ("calibrate-camera {pts_few} {tmp}/cal.toml", ["pts_few.csv", "four reference points"]),
    ("calibrate-camera {pts_text} {tmp}/cal.toml", ["pts_text.csv", "line 3"]),
    ("calibrate-camera {pts_cols} {tmp}/cal.toml", ["pts_cols.csv", "line 2", "four columns"]),
    ("calibrate-camera {pts_line} {tmp}/cal.toml", ["pts_line.csv"]),
    ("calibrate-camera {pts_few} {tmp}/cal.toml --plane-z-m abc", ["--plane-z-m"]),
    # run
    ("run {tmp}/missing.toml", ["missing.toml", "not found"]),
    ("run {dir}", ["a_dir"]),
    ("run {badtoml}", ["bad.toml"]),
    ("run {colour}", ["colour.toml", "colour"]),
    ("run {kp}", ["kp.toml", "align.kp"]),
    ("run {scene}", ["nope_scene.toml"]),
    ("run {file}", ["a_file.txt"]),
    (f"run {P} --set noequals", ["--set", "noequals"]),
    (f"run {P} --set run.nope=1", ["run.nope"]),
    (f"run {P} --set run.timeout_s=-1", ["run.timeout_s"]),
    (f"run {P} --set run.timeout_s=abc", ["run.timeout_s"]),
    (f"run {P} --rig {{tmp}}/nope_rig.toml", ["nope_rig.toml", "not found"]),
    ("hil {tmp}/nope_impact.toml", ["nope_impact.toml", "not found"]),
    (f"hil {HIL} --scene-set carrier.compensation=magic", ["carrier.compensation"]),
    (f"hil {HIL} --scene-set carrier.extra_delay_cycles=-1", ["carrier.extra_delay_cycles"]),
    (f"hil {HIL} --scene-set carrier.cycle_s=0.00125", ["carrier.cycle_s", "multiple"]),
    (f"hil {HIL} --out {{file}}", ["--out", "not a directory"]),
    (f"hil {P}", ["method2.toml"]),
    (f"hil {HIL} --set faults.link_lost_at_s=-1", ["faults.link_lost_at_s"]),
    (f"hil-sweep {HIL} --out {{tmp}}/sw --delays one", ["--delays"]),
    (f"hil-sweep {HIL} --out {{tmp}}/sw --stiffness x", ["--stiffness"]),
    (f"hil-sweep {HIL} --out {{tmp}}/sw --compensation magic", ["--compensation", "magic"]),
    (f"run {P} --rig {MOCK} --rig-set robot.type=warp", ["mock.toml", "robot"]),
    (f"run {P} --rig {MOCK} --rig-set robot.cycles=-1", ["robot.cycles"]),
    (f"run {P} --rig {ROOT / 'rigs/ur5e-lab.toml'} --rig-set robot.force_mode_damping=2",
     ["ur5e-lab.toml", "robot.force_mode_damping"]),
    (f"run {P} --rig {{badtoml}}", ["bad.toml"]),
    (f"run {P} --driver warp", ["--driver", "warp"]),
    (f"run {P} --driver fri", ["robot.robot_ip"]),
    (f"run {P} --fri-port abc", ["--fri-port"]),
    (f"run {P} --driver fri --robot-ip 10.0.0.1 --fri-port 70000", ["robot.port"]),
    (f"run {P} --driver fri --robot-ip 10.0.0.1 --netft 10.0.0.2:abc", ["ft.port"]),
    (f"run {P} --ft warp", ["ft", "warp"]),
    (f"run {P} --out {{file}}", ["--out", "a_file.txt"]),
    (f"run {P} --bogus", ["--bogus"]),
    ("run", ["protocol"]),
    # campaign
    ("campaign {tmp}/missing.toml", ["missing.toml"]),
    ("campaign {camp_missing}", ["runs.0.protocol", "missing.toml"]),
    ("campaign {camp_empty}", ["camp_empty.toml", "runs"]),
    ("campaign {camp_badentry}", ["kp.toml", "align.kp"]),
    ("campaign {badtoml}", ["bad.toml"]),
    ("campaign {colour}", ["colour.toml"]),
    (f"campaign {CAMP} --out {{file}}", ["--out"]),
    (f"campaign {CAMP} --set noequals", ["--set"]),
    (f"campaign {CAMP} --set align.nope=1", ["align.nope"]),
    (f"campaign {CAMP} --driver warp", ["--driver"]),
    (f"campaign {CAMP} --rig {MOCK} --rig-set robot.type=warp", ["robot"]),
    ("campaign", ["campaign_file"]),
    # check
    ("check {tmp}/missing.toml", ["missing.toml", "not found"]),
    ("check {colour}", ["colour.toml", "colour"]),
    ("check {file}", ["a_file.txt"]),
    (f"check {P} {MOCK} {ROOT / 'rigs/sim.toml'}", ["sim.toml", "second rig"]),
    (f"check {P} --rig {MOCK} --driver sim", ["--driver", "--rig"]),
    ("check", ["files"]),
    # analyze
    ("analyze {tmp}/missing.mcap", ["missing.mcap", "not found"]),
    ("analyze {empty}", ["empty.mcap", "empty file"]),
    ("analyze {text}", ["text.mcap", "not an MCAP file"]),
    ("analyze {magic}", ["magic.mcap", "no topic"]),
    ("analyze {foreign}", ["foreign.mcap", "no topic"]),
    ("analyze {dir}", ["a_dir", "directory"]),
    ("analyze {rec} --plots {file}", ["--plots", "a_file.txt"]),
    ("analyze {rec} {text}", ["text.mcap"]),
    ("analyze {rec} --bogus", ["--bogus"]),
    ("analyze", ["recordings"]),
    # compare
    ("compare {tmp}/missing.mcap", ["missing.mcap"]),
    ("compare {empty}", ["empty.mcap"]),
    ("compare {text}", ["text.mcap"]),
    ("compare {magic}", ["magic.mcap"]),
    ("compare {foreign}", ["foreign.mcap"]),
    ("compare {dir}", ["a_dir"]),
    ("compare {rec} --csv {dir}", ["--csv", "a_dir"]),
    ("compare {rec} --csv {nodir}", ["out.csv", "cannot write"]),
    ("compare {rec} {empty}", ["empty.mcap"]),
    ("compare", ["recordings"]),
    # recover
    ("recover {tmp}/missing.mcap", ["missing.mcap"]),
    ("recover {empty}", ["empty.mcap"]),
    ("recover {text}", ["text.mcap"]),
    ("recover {magic}", ["magic.mcap", "nothing"]),
    ("recover {dir}", ["a_dir"]),
    ("recover {rec} -o {rec}", ["must differ"]),
    ("recover {rec} -o {nodir}", ["out.csv", "cannot write"]),
    ("recover", ["recording"]),
    # topics
    ("topics {tmp}/missing.mcap", ["missing.mcap"]),
    ("topics {empty}", ["empty.mcap"]),
    ("topics {text}", ["text.mcap"]),
    ("topics {dir}", ["a_dir"]),
    ("topics --bogus", ["--bogus"]),
    # report
    ("report {tmp}/nowhere", ["nowhere", "not found"]),
    ("report {file}", ["a_file.txt", "not a directory"]),
    ("report {emptydir}", ["emptydir", "no recordings"]),
    ("report {badjson_dir}", ["campaign.json", "JSON"]),
    ("report {listjson_dir}", ["campaign.json", "object"]),
    ("report {tmp} --out {dir}", ["--out", "a_dir"]),
    ("report", ["directory"]),
    # schema
    ("schema bogus", ["bogus", "protocol"]),
    ("schema", ["KIND"]),
    ("schema protocol --write {dir}", ["--write"]),
    ("schema --write {file}", ["a_file.txt"]),
    # calibrate, resimulate (more in tests/test_calibrate.py)
    ("calibrate {tmp}/missing.mcap --fit target.mu --out {tmp}/s.toml", ["missing.mcap"]),
    ("calibrate {text} --fit target.mu --out {tmp}/s.toml", ["text.mcap"]),
    ("calibrate {rec} --fit target.mu --out {tmp}/s.toml", ["driver 'mock'"]),
    ("calibrate {rec} --fit target.nope --out {tmp}/s.toml", ["--fit", "target.nope"]),
    ("calibrate {rec} --fit target.mu=0.01:0.02 --out {tmp}/s.toml", ["exclude the start"]),
    ("calibrate {rec} --fit target.mu --out {file}", ["--out", "exists"]),
    ("calibrate {rec} --out {tmp}/s.toml", ["--fit"]),
    ("resimulate {tmp}/missing.mcap --out {tmp}/o.mcap", ["missing.mcap"]),
    ("resimulate {rec} --out {tmp}/o.mcap", ["no scene", "--scene"]),
    ("resimulate {rec} --out {dir}", ["--out", "a_dir"]),
    # emulate
    ("emulate --remote 127.0.0.1:1 --duration -5", ["--duration"]),
    ("emulate --remote 127.0.0.1:1 --duration nan", ["--duration"]),
    ("emulate --remote 127.0.0.1:1 --port 70000", ["--port"]),
    ("emulate --remote 127.0.0.1:1 --netft-port -2", ["--netft-port"]),
    ("emulate --remote 127.0.0.1:1 --cycle-ms 0", ["--cycle-ms"]),
    ("emulate --remote 127.0.0.1:1 --pacing warp", ["--pacing"]),
    ("emulate --remote 127.0.0.1:1 --loss 150", ["--loss"]),
    ("emulate --remote 127.0.0.1:1 --delay-ms -1", ["--delay-ms"]),
    ("emulate --remote 127.0.0.1:1 --timeout-ms 0", ["--timeout-ms"]),
    ("emulate --remote nohostport", ["--remote"]),
    ("emulate --remote 127.0.0.1:99999", ["--remote"]),
    ("emulate --remote 127.0.0.1:1 --scene {tmp}/nope_scene.toml", ["nope_scene.toml"]),
    ("emulate", ["--remote"]),
    # simulate contact-1dof
    ("simulate contact-1dof --m-t -1", ["--m-t"]),
    ("simulate contact-1dof --m-ri 0", ["--m-ri"]),
    ("simulate contact-1dof --duration -1", ["--duration"]),
    ("simulate contact-1dof --dt 0", ["--dt"]),
    ("simulate contact-1dof --dt 5", ["--dt"]),
    ("simulate contact-1dof --k-c abc", ["--k-c"]),
    ("simulate contact-1dof --csv {nodir}", ["out.csv", "cannot write"]),
    ("simulate contact-1dof --csv {dir}", ["a_dir"]),
    # simulate sweep
    ("simulate sweep {tmp}/missing.toml", ["missing.toml", "not found"]),
    ("simulate sweep {sweep_empty}", ["sweep_empty.toml", "sweep.values"]),
    ("simulate sweep {sweep_field}", ["sweep.parameter"]),
    (f"simulate sweep {SWEEP} --set noequals", ["--set"]),
    (f"simulate sweep {SWEEP} --out {{file}}", ["--out", "a_file.txt"]),
    ("simulate sweep {badtoml}", ["bad.toml"]),
    # friction synth
    ("friction synth --out {tmp}/v.avi --size big", ["--size"]),
    ("friction synth --out {tmp}/v.avi --codec warp", ["--codec"]),
    ("friction synth --out {tmp}/v.avi --fps 0", ["fps"]),
    ("friction synth --out {tmp}/v.avi --mu 2", ["mu"]),
    ("friction synth --out {tmp}/v.avi --start-px 1", ["--start-px"]),
    ("friction synth", ["--out"]),
    # friction estimate
    ("friction estimate {tmp}/missing.avi --px-per-m 1000", ["missing.avi"]),
    ("friction estimate {text} --px-per-m 1000", ["text.mcap"]),
    (f"friction estimate {VIDEO} --px-per-m -1", ["--px-per-m"]),
    (f"friction estimate {VIDEO}", ["--px-per-m", "--object-size-m"]),
    (f"friction estimate {VIDEO} --table-points {{tmp}}/nope.json", ["nope.json"]),
    (f"friction estimate {VIDEO} --table-points {{points}}", ["points.json"]),
    (f"friction estimate {VIDEO} --px-per-m 1000 --confidence 2", ["confidence"]),
    (f"friction estimate {VIDEO} --px-per-m 1000 --marker WARP", ["WARP"]),
    (f"friction estimate {VIDEO} --px-per-m 1000 --plot {{tmp}}/p.jpg", ["p.jpg"]),
    ("friction estimate", ["video"]),
]


def expand(line: str, files: dict[str, str]) -> list[str]:
    return [part.format(**files) for part in line.split()]


def check_one_line(code: int, stdout: str, stderr: str, needles: list[str]) -> None:
    assert "Traceback" not in stdout + stderr, stderr
    lines = [x for x in stderr.splitlines() if x.strip()]
    assert len(lines) == 1, stderr
    assert lines[0].startswith("error: "), lines[0]
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    assert code == 2, (code, lines[0])


def test_the_battery_is_large_and_covers_every_command() -> None:
    assert len(CASES) >= 90
    from test_data_bad_input import CASES as DATA_CASES  # replay, diff, export

    commands = {line.split()[0] if line.split()[0] not in ("simulate", "friction")
                else " ".join(line.split()[:2]) for line, _n in [*CASES, *DATA_CASES]}
    registered = {c.name for c in app.registered_commands} - {"sweep", "limits", "reproduce"}
    groups = {f"{g.name} {c.name or c.callback.__name__}" for g in app.registered_groups
              for c in g.typer_instance.registered_commands if c.callback is not None}
    assert registered | groups <= commands


@pytest.mark.parametrize(("line", "needles"), CASES, ids=[c[0] for c in CASES])
def test_bad_input_is_one_line_exit_2(
    files: dict[str, str], line: str, needles: list[str]
) -> None:
    args = expand(line, files)
    result = runner.invoke(app, args)
    check_one_line(result.exit_code, result.stdout, result.stderr,
                   [n.format(**files) for n in needles])


@pytest.mark.parametrize(
    ("line", "needles"),
    [
        ("analyze {magic}", ["magic.mcap"]),
        ("run {kp}", ["align.kp"]),
        ("emulate --remote 127.0.0.1:1 --duration -5", ["--duration"]),
        ("compare {rec} --csv {dir}", ["--csv"]),
        ("run", ["protocol"]),
    ],
)
def test_bad_input_in_a_subprocess(files: dict[str, str], line: str, needles: list[str]) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "ffexp", *expand(line, files)],
        capture_output=True, text=True, timeout=120, cwd=files["tmp"],
    )
    check_one_line(done.returncode, done.stdout, done.stderr, needles)


def test_recover_of_nothing_writes_nothing(files: dict[str, str]) -> None:
    out = Path(files["tmp"]) / "nothing.mcap"
    result = runner.invoke(app, ["recover", files["magic"], "-o", str(out)])
    assert result.exit_code == 2 and not out.exists()


def test_no_run_directory_is_left_by_a_bad_campaign(files: dict[str, str]) -> None:
    out = Path(files["tmp"]) / "camp_out"
    result = runner.invoke(app, ["campaign", files["camp_badentry"], "--out", str(out)])
    assert result.exit_code == 2
    assert not out.exists() or not any(out.iterdir())


def test_analyze_json_of_a_good_and_a_bad_file_prints_the_good_one(files: dict[str, str]) -> None:
    result = runner.invoke(app, ["analyze", files["rec"], files["text"], "--json"])
    assert result.exit_code == 2
    assert json.loads(result.stdout.splitlines()[0])["file"] == files["rec"]


# -- bad input by class: every case also checks that nothing was created ----------------------
NON_FINITE = ["nan", "inf", "-inf", "1e400"]  # 1e400 overflows to inf when parsed


@pytest.fixture(scope="module")
def by_class(tmp_path_factory: pytest.TempPathFactory, files: dict[str, str]) -> dict[str, str]:
    """Files for the classes: numbers out of range in a protocol, a rig, a scene; rigs
    that are not rigs; a recording with a corrupt chunk."""
    d = tmp_path_factory.mktemp("by_class")
    out: dict[str, Path] = {}

    def write(name: str, text: str | bytes) -> None:
        path = out[Path(name).stem] = d / name
        if isinstance(text, bytes):
            path.write_bytes(text)
        else:
            path.write_text(text)

    base = (ROOT / "protocols/method2.toml").read_text().replace(
        '"../data/scenes/', f'"{ROOT}/data/scenes/')
    write("proto_nan.toml", base + "\n[run]\ntimeout_s = nan\n")
    write("proto_1e400.toml", 'name = "x"\n[run]\ntimeout_s = 1e400\n')
    write("proto_list_inf.toml", 'name = "x"\n[align]\nmethod = "force"\n'
          'kp = [0.0, 0.0, inf, 0.0, 0.0, 0.0]\n')
    write("proto_long.toml", 'name = "x"\n[run]\ntare_s = 1e300\n')
    write("scene_nan.toml", (ROOT / "data/scenes/paper.toml").read_text().replace(
        "gravity = 9.81", "gravity = nan", 1))
    write("proto_scene_nan.toml", base.replace(f"{ROOT}/data/scenes/paper.toml",
                                               str(d / "scene_nan.toml")))
    points = "u,v,x,y\n0,0,0,0\n100,0,0.1,0\n0,100,0,0.1\n100,100,{},0.1\n"
    write("pts_nan.csv", points.format("nan"))
    write("pts_inf.csv", points.format("1e400"))
    write("rig_empty.toml", "")
    write("rig_comments.toml", "# nothing but a comment\n\n")
    write("rig_json.toml", '{"robot": {"type": "sim"}}\n')
    write("rig_binary.toml", b"\x89PNG\r\n\x1a\n\x00\x00\xff\xfe")
    write("rig_protocol.toml", 'name = "method2"\n[run]\ntimeout_s = 1.0\n')
    write("rig_inf.toml", '[robot]\ntype = "mock"\ncycle_s = inf\n[ft]\ntype = "mock"\n')
    write("rig_long.toml", '[robot]\ntype = "fri1"\nrobot_ip = "10.0.0.1"\n'
          'connect_timeout_s = 1e12\n[ft]\ntype = "fri-estimate"\n')
    # two devices with ids (drivers/rig.py): the chaser's tables, then a [carrier]
    mock = '[robot]\ntype = "mock"\n[ft]\ntype = "mock"\n'
    fri = '[robot]\ntype = "fri1"\nrobot_ip = "10.0.0.1"\n[ft]\ntype = "netft"\n' \
          'host = "192.168.1.1"\n'
    for name, text in {
        "rig_same_id": 'id = "arm"\n' + mock + '[carrier]\nid = "arm"\n'
                       '[carrier.robot]\ntype = "mock"\n[carrier.ft]\ntype = "mock"\n',
        "rig_default_ids": 'id = "carrier"\n' + mock + '[carrier.robot]\ntype = "mock"\n'
                           '[carrier.ft]\ntype = "mock"\n',
        "rig_no_carrier_ft": mock + '[carrier.robot]\ntype = "mock"\n',
        "rig_bad_id": mock + '[carrier]\nid = "Carrier Arm"\n[carrier.robot]\ntype = "mock"\n'
                      '[carrier.ft]\ntype = "mock"\n',
        "rig_same_robot_ip": fri + '[carrier.robot]\ntype = "ur"\nrobot_ip = "10.0.0.1"\n'
                             '[carrier.ft]\ntype = "ur-wrench"\n',
        "rig_same_ft": fri + '[carrier.robot]\ntype = "ur"\nrobot_ip = "10.0.0.2"\n'
                       '[carrier.ft]\ntype = "netft"\nhost = "192.168.1.1"\n',
        "rig_same_port": '[robot]\ntype = "fri1"\nrobot_ip = "127.0.0.1"\n[ft]\n'
                         'type = "fri-estimate"\n[carrier.robot]\ntype = "fri1"\n'
                         'robot_ip = "127.0.0.1"\n[carrier.ft]\ntype = "fri-estimate"\n',
        "rig_carrier_pairing": mock + '[carrier.robot]\ntype = "mock"\n[carrier.ft]\n'
                               'type = "fri-estimate"\n',
        "rig_carrier_type": mock + '[carrier.robot]\ntype = "warp"\n[carrier.ft]\n'
                            'type = "mock"\n',
        "rig_carrier_key": mock + '[carrier]\ncolour = "red"\n[carrier.robot]\ntype = "mock"\n'
                           '[carrier.ft]\ntype = "mock"\n',
        "rig_carrier_port": mock + '[carrier.robot]\ntype = "fri1"\nrobot_ip = "10.0.0.5"\n'
                            'port = 70000\n[carrier.ft]\ntype = "fri-estimate"\n',
        "rig_with_carrier": mock + '[carrier.robot]\ntype = "mock"\n[carrier.ft]\n'
                            'type = "mock"\n',
    }.items():
        write(f"{name}.toml", text)
    for name in ("fifo.toml", "fifo.mcap"):  # a reader would block on these forever
        path = out[name.replace(".", "_")] = d / name
        os.mkfifo(path)
    write("camp_self.toml", 'name = "c"\n[[runs]]\nprotocol = "camp_self.toml"\n')
    data = bytearray(Path(files["rec"]).read_bytes())
    middle = len(data) // 2
    data[middle:middle + 16] = bytes(b ^ 0xFF for b in data[middle:middle + 16])
    write("corrupt.mcap", bytes(data))
    return {k: str(v) for k, v in out.items()} | {"ctmp": str(d)}


# (command line with {placeholders} ({out}: a directory that must stay absent or empty),
#  the words the one error line must contain)
CLASS_CASES: dict[str, list[tuple[str, list[str]]]] = {
    "set_non_finite": [
        *[(f"run {P} --set run.timeout_s={v} --out {{out}}", ["run.timeout_s", "finite"])
          for v in NON_FINITE],
        *[(f"run {P} --set align.kp=[0,0,{v},0,0,0] --out {{out}}", ["align.kp.2", "finite"])
          for v in ("nan", "inf")],
        (f"run {P} --set approach.speed_mps=nan --out {{out}}", ["approach.speed_mps"]),
        (f"run {P} --set run.tare_s=1e308 --out {{out}}", ["run.tare_s", "at most"]),
        (f"run {P} --set run.tf_period_s=1e9 --out {{out}}", ["run.tf_period_s", "at most"]),
        (f"campaign {CAMP} --set run.timeout_s=inf --out {{out}}", ["run.timeout_s", "finite"]),
        (f"campaign {CAMP} --set align.kp=[0,0,nan,0,0,0] --out {{out}}", ["align.kp.2"]),
        (f"sweep {P} --vary align.k_ri[3]=0.1,0.2 --set run.timeout_s=nan --out {{out}}",
         ["run.timeout_s"]),
        *[(f"sweep {P} --vary align.k_ri[3]={v},0.5 --out {{out}}", ["--vary", "finite"])
          for v in ("nan", "inf", "1e400")],
        (f"sweep {P} --vary align.f_ref=[0,0,nan,0,0,0] --out {{out}}", ["--vary", "finite"]),
        (f"limits {P} --key align.k_ri[3] --range 0:inf --out {{out}}", ["--range"]),
        (f"run {P} --rig {MOCK} --rig-set robot.cycle_s=nan --out {{out}}",
         ["robot.cycle_s", "finite"]),
    ],
    "option_non_finite": [
        *[(f"emulate --remote 127.0.0.1:1 --jitter-ms {v}", ["--jitter-ms", "finite"])
          for v in NON_FINITE],
        ("emulate --remote 127.0.0.1:1 --camera-fps inf", ["--camera-fps"]),
        ("simulate contact-1dof --m-t nan --csv {out}/x.csv", ["--m-t"]),
        ("simulate contact-1dof --v0 1e400 --csv {out}/x.csv", ["--v0", "finite"]),
        ("diff {rec} {rec} --rtol nan", ["--rtol", "finite"]),
        ("friction synth --out {out}/v.avi --v0 inf", ["--v0", "finite"]),
        (f"friction estimate {VIDEO} --px-per-m nan --plot {{out}}/p.png", ["--px-per-m"]),
        (f"sweep {P} --vary align.k_ri[3]=0.1 --seeds 99999999999999999999 --out {{out}}",
         ["--seeds", "out of range"]),
        (f"sweep {P} --vary align.k_ri[3]=0.1 --seeds 100000000 --out {{out}}", ["--seeds"]),
        (f"limits {P} --key align.k_ri[3] --range 0:1 --coarse 0 --out {{out}}", ["--coarse"]),
        (f"run {P} --fri-port 99999999999999999999 --out {{out}}", ["--fri-port"]),
    ],
    "file_numbers": [
        ("run {proto_nan} --out {out}", ["proto_nan.toml", "run.timeout_s", "finite"]),
        ("run {proto_1e400} --out {out}", ["proto_1e400.toml", "run.timeout_s", "finite"]),
        ("run {proto_list_inf} --out {out}", ["proto_list_inf.toml", "align.kp.2"]),
        ("run {proto_long} --out {out}", ["proto_long.toml", "run.tare_s", "at most"]),
        ("run {proto_scene_nan} --out {out}", ["scene_nan.toml", "gravity", "finite"]),
        (f"run {P} --rig {{rig_inf}} --out {{out}}", ["rig_inf.toml", "robot.cycle_s"]),
        (f"run {P} --rig {{rig_long}} --out {{out}}",
         ["rig_long.toml", "robot.connect_timeout_s"]),
        *[(f"calibrate-camera {{{name}}} {{out}}/cal.toml", [f"{name}.csv", "line 5", "finite"])
          for name in ("pts_nan", "pts_inf")],
    ],
    "rig_not_a_rig": [
        *[(f"run {P} --rig {{{name}}} --out {{out}}", [f"{name}.toml"])
          for name in ("rig_empty", "rig_comments", "rig_json", "rig_binary", "rig_protocol")],
        (f"campaign {CAMP} --rig {{rig_empty}} --out {{out}}", ["rig_empty.toml", "empty"]),
    ],
    "os_refusal": [
        (f"run {P} --rt --cpu 99 --out {{out}}", ["--cpu", "99"]),
        (f"run {P} --rt --cpu -1 --out {{out}}", ["--cpu", "-1"]),
        (f"run {P} --rt --cpu 0 --cpu 4096 --out {{out}}", ["--cpu", "4096"]),
        ("emulate --remote 127.0.0.1:1 --rt --cpu 99", ["--cpu", "99"]),
    ],
    "non_regular_file": [
        ("run {fifo_toml} --out {out}", ["fifo.toml", "FIFO"]),
        ("run /dev/null --out {out}", ["/dev/null", "a device"]),
        (f"run {P} --rig {{fifo_toml}} --out {{out}}", ["fifo.toml", "FIFO"]),
        ("campaign {fifo_toml} --out {out}", ["fifo.toml", "FIFO"]),
        ("analyze {fifo_mcap}", ["fifo.mcap", "FIFO"]),
        ("resimulate {fifo_mcap} --out {out}/r.mcap", ["fifo.mcap", "FIFO"]),
        ("calibrate {fifo_mcap} --fit target.mu --out {ctmp}/fifo_cal.toml",
         ["fifo.mcap", "FIFO"]),
        ("friction estimate {fifo_mcap} --px-per-m 1000 --plot {out}/p.png",
         ["fifo.mcap", "FIFO"]),
        ("calibrate-camera {fifo_toml} {out}/cal.toml", ["fifo.toml", "FIFO"]),
        (f"friction estimate {VIDEO} --table-points {{fifo_toml}} --plot {{out}}/p.png",
         ["fifo.toml", "FIFO"]),
    ],
    "conflicting_options": [
        (f"run {P} --rig {MOCK} --driver sim --out {{out}}", ["--driver", "--rig"]),
        (f"campaign {CAMP} --rig {MOCK} --driver mock --out {{out}}", ["--driver", "--rig"]),
        ("emulate --robot ur5e --remote 127.0.0.1:1 --duration 0.1", ["--remote", "ur5e"]),
        ("emulate --remote 127.0.0.1:1 --listen 127.0.0.1:30004", ["--listen", "lwr4"]),
        (f"run {P} --scene-set scene.target.mu=0.006 --out {{out}}", ["--scene-set"]),
        (f"run {P} --scene-set noequals --out {{out}}", ["--scene-set", "noequals"]),
        (f"limits {P} --key align.f_ref[2] --key align.f_ref[2] --range 0:1 --range 0:1 "
         "--out {out}", ["--key", "the same key twice"]),
    ],
    "overwrite": [
        ("resimulate {rec} --out {file}", ["--out", "a_file.txt", "exists"]),
        ("resimulate {rec} --out {rec}", ["--out", "the recording itself"]),
        ("calibrate {rec} --fit target.mu --out {file}", ["--out", "exists"]),
        ("recover {rec} -o {rec}", ["must differ"]),
    ],
    "wrong_kind_of_file": [
        (f"run {P} --rig {P} --out {{out}}", ["method2.toml", "is a run protocol, not a rig"]),
        (f"run {CAMP} --out {{out}}", ["paper.toml", "is a campaign, not a run protocol"]),
        (f"campaign {P} --out {{out}}", ["method2.toml", "is a run protocol, not a campaign"]),
        (f"run {SCENE} --out {{out}}", ["paper.toml", "is a scene, not a run protocol"]),
        (f"run {P} --rig {SCENE} --out {{out}}", ["paper.toml", "is a scene, not a rig"]),
        (f"run {SWEEP} --out {{out}}", ["is a sweep protocol, not a run protocol"]),
        (f"campaign {MOCK} --out {{out}}", ["mock.toml", "is a rig, not a campaign"]),
        (f"hil {P} --out {{out}}", ["method2.toml",
                                    "is a run protocol, not an impact protocol", "ffexp run"]),
        (f"hil {CAMP} --out {{out}}", ["paper.toml", "is a campaign, not an impact protocol"]),
        (f"simulate sweep {P} --out {{out}}", ["method2.toml",
                                               "is a run protocol, not a sweep protocol"]),
        (f"simulate sweep {HIL} --out {{out}}", ["hil_impact.toml", "is an impact protocol, "
                                                 "not a sweep protocol", "ffexp hil"]),
        (f"reproduce --config {CAMP} --out {{out}}", ["paper.toml", "is a campaign, not a study"]),
        (f"reproduce --config {SWEEP} --out {{out}}", ["sec3_stiffness.toml",
                                                       "is a sweep protocol, not a study"]),
        ("campaign {camp_self} --out {out}", ["runs.0.protocol", "this campaign itself"]),
        (f"run {P} --rig {ROOT / 'rigs/ur5e-sim.toml'} --ft sim --out {{out}}",
         ["ur5e-sim.toml", "ft.type"]),
        # a UR5e scene on the KRC's LWR4+ (in-process here): the scene's arm, not the rig
        (f"run {P} --set scene.file=\"../data/scenes/paper-ur5e.toml\" --out {{out}}",
         ["paper-ur5e.toml", "arm.model", "'ur5e'", "drives the lwr4"]),
        (f"campaign {CAMP} --scene-set arm.model=\"ur5e\" --out {{out}}",
         ["paper.toml", "arm", "UR5e"]),
    ],
    "refused_address": [
        (f"run {P} --driver fri --robot-ip 999.1.1.1 --out {{out}}",
         ["robot.robot_ip", "999.1.1.1"]),
        (f"run {P} --driver fri --robot-ip 10.0.0.1 --netft 999.0.0.1 --out {{out}}",
         ["ft.host", "999.0.0.1"]),
        (f"run {P} --driver ur --robot-ip 999.1.1.1 --out {{out}}",
         ["robot.robot_ip", "999.1.1.1"]),
        (f"run {P} --driver ur --robot-ip bad/host --out {{out}}", ["robot.robot_ip"]),
        (f"run {P} --rig {ROOT / 'rigs/ur5e-lab.toml'} --robot-ip 999.1.1.1 --out {{out}}",
         ["ur5e-lab.toml", "robot.robot_ip"]),
        ("emulate --robot ur5e --listen 10.255.255.1:30004 --duration 0.1", ["--listen"]),
    ],
    "negative_or_huge": [
        (f"run {P} --set seed=-1 --out {{out}}", ["seed"]),
        (f"run {P} --scene-set target.mu=-1 --out {{out}}", ["target.mu"]),
        (f"run {P} --set scene.target.mu=nan --out {{out}}", ["target.mu", "finite"]),
        (f"run {P} --scene-set target.mu=1e400 --out {{out}}", ["target.mu", "finite"]),
        # a typo'd timestep: refused, not hours of steps
        (f"run {P} --scene-set physics.timestep=1e-9 --out {{out}}", ["physics.timestep",
                                                                     "0.00001"]),
        ("emulate --robot ur5e --duration -1", ["--duration"]),
    ],
    "rig_devices": [  # two devices with ids: one line each, naming the file and the field
        (f"run {P} --rig {{rig_same_id}} --out {{out}}", ["rig_same_id.toml", "carrier.id",
                                                         "one id"]),
        (f"run {P} --rig {{rig_default_ids}} --out {{out}}", ["rig_default_ids.toml",
                                                             "'carrier'", "one id"]),
        (f"run {P} --rig {{rig_no_carrier_ft}} --out {{out}}", ["rig_no_carrier_ft.toml",
                                                               "carrier", "F/T sensor"]),
        (f"run {P} --rig {{rig_bad_id}} --out {{out}}", ["rig_bad_id.toml", "carrier.id"]),
        (f"run {P} --rig {{rig_same_robot_ip}} --out {{out}}",
         ["rig_same_robot_ip.toml", "carrier.robot.robot_ip", "10.0.0.1"]),
        (f"run {P} --rig {{rig_same_ft}} --out {{out}}",
         ["rig_same_ft.toml", "carrier.ft.host", "192.168.1.1:49152", "ft.host"]),
        (f"run {P} --rig {{rig_same_port}} --out {{out}}",
         ["rig_same_port.toml", "127.0.0.1:49938", "two devices"]),
        (f"run {P} --rig {{rig_carrier_pairing}} --out {{out}}",
         ["rig_carrier_pairing.toml", "carrier", "fri-estimate"]),
        (f"run {P} --rig {{rig_carrier_type}} --out {{out}}",
         ["rig_carrier_type.toml", "carrier.robot", "warp"]),
        (f"run {P} --rig {{rig_carrier_key}} --out {{out}}",
         ["rig_carrier_key.toml", "carrier.colour", "unknown key"]),
        (f"run {P} --rig {{rig_carrier_port}} --out {{out}}",
         ["rig_carrier_port.toml", "carrier.robot.port"]),
        (f"run {P} --rig {{rig_with_carrier}} --out {{out}}",
         ["rig_with_carrier.toml", "carrier", "ffexp hil"]),
        (f"run {P} --rig {MOCK} --rig-set carrier.id=chaser --out {{out}}",
         ["mock.toml", "carrier"]),
    ],
    "corrupt_recording": [
        (f"{cmd} {{corrupt}}{rest}", ["corrupt.mcap", "ffexp recover"])
        for cmd, rest in (("analyze", ""), ("compare", ""), ("compare", " --csv {out}/c.csv"),
                          ("export", " --out {out}"), ("diff", " {rec}"),
                          ("replay", " --out {out}/r.mcap"))
    ],
}


@pytest.mark.parametrize(
    ("line", "needles"),
    [case for cases in CLASS_CASES.values() for case in cases],
    ids=[f"{cls}: {line}" for cls, cases in CLASS_CASES.items() for line, _ in cases])
def test_bad_input_by_class_is_one_line_exit_2_and_creates_nothing(
        files: dict[str, str], by_class: dict[str, str], tmp_path: Path, line: str,
        needles: list[str]) -> None:
    out = tmp_path / "out"
    names = files | by_class | {"out": str(out)}
    result = runner.invoke(app, [part.format(**names) for part in line.split()])
    check_one_line(result.exit_code, result.stdout, result.stderr,
                   [n.format(**names) for n in needles])
    assert not out.exists() or not any(out.iterdir()), sorted(out.iterdir())
    assert not list(Path.cwd().glob("runs/*.mcap.tmp"))


def test_every_class_has_several_cases() -> None:
    assert all(len(cases) >= 4 for cases in CLASS_CASES.values())


@pytest.mark.parametrize("line", [
    "run {proto_nan} --out {out}", f"run {P} --set run.timeout_s=1e400 --out {{out}}",
    "analyze {corrupt}", f"run {P} --rt --cpu 99 --out {{out}}", f"hil {P} --out {{out}}"])
def test_the_classes_in_a_subprocess(files: dict[str, str], by_class: dict[str, str],
                                     tmp_path: Path, line: str) -> None:
    out = tmp_path / "out"
    names = files | by_class | {"out": str(out)}
    done = subprocess.run([sys.executable, "-m", "ffexp", *[p.format(**names)
                                                           for p in line.split()]],
                          capture_output=True, text=True, timeout=120, cwd=tmp_path)
    check_one_line(done.returncode, done.stdout, done.stderr, [])
    assert not out.exists() and not (tmp_path / "runs").exists()
