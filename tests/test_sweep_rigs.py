"""Studies on a simulated arm's rig: ``ffexp sweep``, ``limits`` and ``reproduce`` with
``--rig``, ``--driver`` and ``--rig-set``.

A study's run on the UR5e (or FR3) simulator is the run ``ffexp run --rig`` makes with the
same overrides, bit for bit; the batch executor gives the same rows; the rig is part of
a run's id only when one is given (the built-in rig keeps the ids of before); a rig with
a real or emulated robot, a Net F/T box or a camera is refused before anything is made.
Runs are short: the approach is sped up so that the tool touches the target after about
1 s and aligns under ALIGN's force loop in the second.
"""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pandas as pd
import pytest
from typer.testing import CliRunner

from drivers.description.scene import load_scene
from ffexp.cli import app
from ffexp.diff import diff
from ffexp.protocol import load_run_protocol, scene_path
from ffexp.recording import load
from ffexp.rig_choice import RigChoice
from ffexp.sweeps import keys, plan, reproduce, rigs, table
from ffexp.sweeps.worker import RUN_FILE, RUNS_DIR, Job, read_row, run_one

ROOT = Path(__file__).resolve().parents[1]
P1 = ROOT / "protocols/method1_case1.toml"
UR_RIG = ROOT / "rigs/ur5e-sim.toml"
SHORT = ["--set", "run.timeout_s=2", "--set", "approach.speed_mps=0.1"]
VARY = "align.f_ref[2]=0.8,1.2"
cli = CliRunner()

# the two simulated arms: (the rig options, the rows' rig, the robot type)
ARMS = {
    "ur5e": (["--rig", str(UR_RIG)], str(UR_RIG), "ur-sim"),
    "fr3": (["--driver", "franka-sim"], "<built-in franka-sim rig>", "franka-sim"),
}


def rows_of(res: Any) -> list[dict[str, Any]]:
    assert res.exit_code == 0, res.output
    return [json.loads(x) for x in res.stdout.splitlines() if x.startswith("{")]


def sweep(out: Path, rig_args: list[str], executor: str = "local:1") -> list[dict[str, Any]]:
    return rows_of(cli.invoke(app, [
        "sweep", str(P1), *rig_args, "--vary", VARY, *SHORT, "--lean", "--executor",
        executor, "--out", str(out), "--json", "--no-figures"]))


@pytest.fixture(scope="module")
def swept(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, list[Any]]]:
    """Each arm's sweep on the process pool (one worker): its directory and rows."""
    base = tmp_path_factory.mktemp("arms")
    return {arm: (base / arm, sweep(base / arm, args)) for arm, (args, _, _) in ARMS.items()}


@pytest.mark.parametrize("arm", list(ARMS))
def test_a_sweep_on_an_arms_simulator_is_ffexp_run_on_it_bit_for_bit(
        tmp_path: Path, swept: dict[str, tuple[Path, list[Any]]], arm: str) -> None:
    rig_args, rig_name, robot_type = ARMS[arm]
    out, rows = swept[arm]
    assert [r["align.f_ref[2]"] for r in rows] == [0.8, 1.2]
    assert all(r["rig"] == rig_name and r["error"] is None for r in rows)
    # the runs made contact and the varied f_ref acted on ALIGN's force loop
    assert all(r["first_contact_s"] is not None and r["first_contact_s"] < 1.5 for r in rows)
    assert rows[0]["mean_fz_align_n"] != rows[1]["mean_fz_align_n"]
    assert json.loads((out / "sweep.json").read_text())["rig"] == rig_name
    csv = pd.read_csv(out / "results.csv")
    assert list(csv["rig"]) == [rig_name] * 2 and list(csv.columns[:3]) == [
        "run_id", "target", "rig"]
    swept_rec = load(out / RUNS_DIR / rows[1]["run_id"] / RUN_FILE)
    meta = swept_rec.metadata["run"]
    assert meta["driver"] == robot_type  # the arm's simulator ran it, not the LWR4+'s
    # the same run made by `ffexp run`, with the overrides the sweep's run was given
    given = [o for o in json.loads(meta["overrides"]) if not o.startswith("scene.file=")]
    assert any(o.startswith("align.f_ref=") for o in given)
    res = cli.invoke(app, ["run", str(P1), *rig_args, "--lean", "--out", str(tmp_path),
                           *(x for o in given for x in ("--set", o))])
    assert res.exit_code in (0, 4), res.output
    alone = load(next(tmp_path.glob("*.mcap")))
    assert alone.metadata["run"]["driver"] == robot_type
    result = diff(swept_rec, alone, rtol=0.0, atol=0.0)
    assert result.ok and not result.only_a and not result.only_b
    assert len(result.topics) >= 5 and all(t.paired > 0 for t in result.topics)
    assert all(t.max_abs == 0.0 for t in result.topics)


@pytest.mark.parametrize("arm", list(ARMS))
def test_the_batch_executor_gives_the_same_rows(
        tmp_path: Path, swept: dict[str, tuple[Path, list[Any]]], arm: str) -> None:
    _out, rows = swept[arm]
    batched = sweep(tmp_path / "batch", ARMS[arm][0], executor="local:1,batch:2")
    assert table.without_wall_time(batched) == table.without_wall_time(rows)
    assert len(batched) == 2 and all(r["aligned"] is not None for r in batched)


def test_limits_on_the_ur5e_simulator(tmp_path: Path) -> None:
    out = tmp_path / "lim"
    res = cli.invoke(app, ["limits", str(P1), "--key", "align.f_ref[2]", "--range",
                           "0.4:1.6", "--coarse", "2", "--resolution", "1.2", "--driver",
                           "ur-sim", *SHORT, "--executor", "local:1", "--out", str(out)])
    assert res.exit_code == 0, res.output
    saved = json.loads((out / "limits.json").read_text())
    assert saved["rig"] == "<built-in ur-sim rig>"
    csv = pd.read_csv(out / "results.csv")
    assert sorted(csv["align.f_ref[2]"]) == [0.4, 1.6]
    assert set(csv["rig"]) == {"<built-in ur-sim rig>"} and csv["error"].isna().all()
    for rid in csv["run_id"]:
        rec = load(out / RUNS_DIR / rid / RUN_FILE)
        assert rec.metadata["run"]["driver"] == "ur-sim"


def test_reproduce_validates_and_plans_every_run_on_the_rig(tmp_path: Path) -> None:
    config = ROOT / "protocols/reproduce.toml"
    rig = rigs.study_rig(RigChoice(path=UR_RIG))
    assert rig is not None
    study = reproduce.load(config, rig=rig)
    inputs = tmp_path / "inputs"
    for role, target in study.targets.items():
        assert target.rig is rig and target.rig_name == str(UR_RIG)
        folder = target.snapshot(inputs)
        job = target.job([], {}, 1, tmp_path, folder)
        assert job.columns["rig"] == str(UR_RIG)
        choice = job.rig_choice()
        # the worker reads the rig and the scene it names from the inputs folder
        assert choice.path == folder / rigs.RIG_FILE and choice.path.read_bytes() == \
            UR_RIG.read_bytes()
        moved = [o for o in choice.overrides if o.startswith("robot.scene_file=")]
        assert len(moved) == 1 and str(folder) in moved[0], role
        assert (folder / "rig-robot-scene_file.toml").read_bytes() == (
            ROOT / "data/scenes/paper-ur5e.toml").read_bytes()
        # the scene the study's points are checked against is the UR5e's
        assert target.scene.arm.model == "ur5e"
    for search in study.searches:
        assert search.target.rig is rig
    # and the command takes it: a study on the emulator's rig is refused before any run
    res = cli.invoke(app, ["reproduce", "--config", str(config), "--rig",
                           str(ROOT / "rigs/emulator.toml"), "--out", str(tmp_path / "r")])
    assert res.exit_code == 2 and "rigs/emulator.toml: robot.type:" in res.stderr
    assert not (tmp_path / "r").exists()


def test_reproduce_runs_on_the_fr3_simulator(tmp_path: Path) -> None:
    config = ROOT / "tests/data/study_nominal.toml"  # the paper's 5 runs, nominal scene
    out = tmp_path / "r"
    res = cli.invoke(app, ["reproduce", "--config", str(config), "--driver", "franka-sim",
                           *SHORT, "--executor", "local:1", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert json.loads((out / "reproduce.json").read_text())["rig"] == \
        "<built-in franka-sim rig>"
    csv = pd.read_csv(out / "results.csv")
    assert len(csv) == 5 and set(csv["target"]) == {"I-1", "I-2", "II-0.8", "II-1.5", "III"}
    assert set(csv["rig"]) == {"<built-in franka-sim rig>"} and csv["error"].isna().all()
    for rid in csv["run_id"]:
        assert load(out / RUNS_DIR / rid / RUN_FILE).metadata["run"]["driver"] == "franka-sim"


# -- run ids -----------------------------------------------------------------------------
def _old_ident(protocol: Path, fixed: tuple[str, ...]) -> str:
    """A target's identity as plan.Target computed it before studies took a rig."""
    proto = load_run_protocol(protocol, fixed)
    scene = load_scene(scene_path(protocol, proto), proto.scene.set)
    digest = hashlib.sha1(usedforsecurity=False)
    digest.update(proto.model_dump_json(exclude={"scene"}).encode())
    digest.update(scene.model_dump_json().encode())
    return f"{proto.name}:{digest.hexdigest()[:12]}"


def _ids(target: plan.Target, tmp_path: Path) -> list[str]:
    key = keys.parse_key("align.f_ref[2]")
    return [target.job([key], {key.text: v}, target.seed, tmp_path, tmp_path).run_id
            for v in (0.8, 1.2)]


def test_run_ids_without_a_rig_are_those_of_before_and_each_rig_has_its_own(
        tmp_path: Path) -> None:
    fixed = ("run.timeout_s=2",)
    bare = plan.Target(P1, fixed)
    assert bare.ident == _old_ident(P1, fixed)
    key = keys.parse_key("align.f_ref[2]")
    assert _ids(bare, tmp_path) == [
        keys.run_id(_old_ident(P1, fixed), {key.text: v}, bare.seed, fixed)
        for v in (0.8, 1.2)]
    # the built-in rig named as it is (--driver sim) is no rig: the same ids
    assert rigs.study_rig(RigChoice(driver="sim")) is None
    on = {name: plan.Target(P1, fixed, rig=rigs.study_rig(choice)) for name, choice in {
        "ur5e file": RigChoice(path=UR_RIG),
        "ur-sim": RigChoice(driver="ur-sim"),
        "franka-sim": RigChoice(driver="franka-sim"),
        "sim, changed": RigChoice(overrides=("robot.start_cycles=50",), driver="sim"),
        "ur5e file, changed": RigChoice(path=UR_RIG,
                                        overrides=("robot.force_mode_damping=0.01",)),
    }.items()}
    ids = {name: _ids(t, tmp_path) for name, t in on.items()}
    ids["none"] = _ids(bare, tmp_path)
    every = [i for pair in ids.values() for i in pair]
    assert len(set(every)) == len(every)  # every rig, every point: its own id
    # the same rig again (a copy of its file elsewhere) is the same rig: the same ids
    copy = tmp_path / "elsewhere" / "my-ur.toml"
    copy.parent.mkdir()
    copy.write_text(UR_RIG.read_text().replace(
        '"../data/scenes/paper-ur5e.toml"', json.dumps(str(ROOT / "data/scenes/paper-ur5e.toml"))))
    again = plan.Target(P1, fixed, rig=rigs.study_rig(RigChoice(path=copy)))
    assert _ids(again, tmp_path) == ids["ur5e file"]


def test_a_row_done_before_rigs_gets_the_rig_column(tmp_path: Path) -> None:
    job = Job("abc123", str(P1), (), str(tmp_path),
              {"target": "m", "rig": rigs.BUILTIN, "seed": 1})
    (tmp_path / RUNS_DIR / "abc123").mkdir(parents=True)
    old = {"run_id": "abc123", "target": "m", "seed": 1, "aligned": True, "error": None}
    (tmp_path / RUNS_DIR / "abc123" / "row.json").write_text(json.dumps(old))
    row = run_one(job)  # done: read back, not run
    assert row["rig"] == rigs.BUILTIN and row["aligned"] is True
    assert list(row)[:3] == ["run_id", "target", "rig"]
    assert read_row(tmp_path, "abc123") is not None


# -- refused rigs --------------------------------------------------------------------------
REFUSED = [
    (["--rig", "rigs/ur5e-lab.toml"], "rigs/ur5e-lab.toml: robot.type: 'ur'"),
    (["--rig", "rigs/emulator.toml"], "rigs/emulator.toml: robot.type: 'fri1'"),
    (["--rig", "rigs/franka-emulator.toml"], "rigs/franka-emulator.toml: robot.type:"),
    (["--driver", "ur"], "<built-in ur rig>: robot.type: 'ur'"),
    (["--driver", "mock"], "<built-in mock rig>: robot.type: 'mock'"),
    (["--rig-set", "ft={type = 'netft', host = '127.0.0.1'}"],
     "<built-in sim rig>: ft.type: 'netft'"),
    (["--rig", "rigs/sim.toml", "--rig-set", "tracker={type = 'camera', source = '0'}"],
     "rigs/sim.toml: tracker.type: 'camera'"),
    (["--rig", "rigs/hil-sim.toml"], "rigs/hil-sim.toml: carrier:"),
]


@pytest.mark.parametrize("command", ["sweep", "limits"])
@pytest.mark.parametrize(("extra", "needle"), REFUSED, ids=[" ".join(r[0]) for r in REFUSED])
def test_a_rig_not_simulated_in_process_is_refused(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, command: str, extra: list[str],
        needle: str) -> None:
    monkeypatch.chdir(ROOT)  # the rig files as a user names them
    out = tmp_path / "never"
    study = ["--vary", VARY] if command == "sweep" else ["--key", "align.f_ref[2]",
                                                         "--range", "0.4:1.6"]
    res = cli.invoke(app, [command, str(P1), *study, *extra, "--out", str(out)])
    assert res.exit_code == 2, res.output
    err = res.stderr.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {needle}"), res.stderr
    assert "Traceback" not in res.output
    assert not out.exists()


def test_a_lab_rig_refused_as_a_subprocess(tmp_path: Path) -> None:
    out = tmp_path / "x"
    res = subprocess.run(
        [sys.executable, "-m", "ffexp", "sweep", "protocols/method1_case1.toml", "--rig",
         "rigs/lwr4-lab.toml", "--vary", VARY, "--out", str(out)],
        capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert res.returncode == 2
    assert res.stderr.strip().splitlines() == [res.stderr.strip()]
    assert res.stderr.startswith("error: rigs/lwr4-lab.toml: robot.type: 'fri1' is not "
                                 "simulated in this process")
    assert not out.exists()
