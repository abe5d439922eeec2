"""ffexp replay, diff and export on one short simulated run (issue 15, deliverables 3-5).

One run of Method I case I on the simulator through ``run_file`` (the real path:
metadata, attachments, every topic), cut at 4.2 s of run time, after the tool
has met the target and ALIGN has begun; every test here replays, diffs or
exports that one recording.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from ffexp.analysis import metrics
from ffexp.cli import app
from ffexp.contracts import Phase
from ffexp.diff import diff
from ffexp.experiment import run_file
from ffexp.export import column_names, element_names
from ffexp.recording import load
from ffexp.recording.topics import CDR_TOPICS
from ffexp.replay import Inputs, replay

ROOT = Path(__file__).resolve().parents[1]
PROTOCOL = ROOT / "protocols/method1_case1.toml"
runner = CliRunner()
#: k_ri of the protocol with k_yp (element 1) changed from 0.2 to 0.5
K_RI_CHANGED = "align.k_ri=[0.0, 0.5, 0.0, 0.5, 0.0, 0.0]"
INTENT = ("given", "pose", "stiffness", "damping", "wrench")


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("runs")
    result = run_file(PROTOCOL, ["run.timeout_s=4.2"], out_dir=out)
    rec = load(result.path, ["/runner/phase"])
    phases = [m["phase"] for m in rec.json["/runner/phase"].messages]
    assert "ALIGN" in phases, phases  # the replay below must exercise the method
    return result.path


@pytest.fixture(scope="module")
def same(run: Path) -> Path:
    out = run.with_name("same.mcap")
    replay(run, out)
    return out


@pytest.fixture(scope="module")
def changed(run: Path) -> Path:
    out = run.with_name("kyp.mcap")
    result = runner.invoke(app, ["replay", str(run), "--set", K_RI_CHANGED, "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "open-loop replay" in result.stdout
    return out


def test_own_protocol_reproduces_every_recorded_command(run: Path, same: Path) -> None:
    a, b = load(run), load(same)
    ca, cb = a.topic("/control/command"), b.topic("/control/command")
    assert len(ca) == len(cb) == len(a.topic("/robot/state")) > 800
    np.testing.assert_array_equal(ca.log_time_ns, cb.log_time_ns)
    for name in INTENT:
        np.testing.assert_allclose(cb[name], ca[name], rtol=1e-12, atol=1e-12, err_msg=name)
    # and why: the estimate and the terms of every cycle, the phases at the same times
    for topic in ("/estimator/state", "/control/terms"):
        for name, values in a.topic(topic).fields.items():
            np.testing.assert_allclose(b.topic(topic)[name], values, rtol=1e-12, atol=1e-12,
                                       err_msg=f"{topic}.{name}")
    pa, pb = a.json["/runner/phase"], b.json["/runner/phase"]
    assert [m["phase"] for m in pb.messages] == [m["phase"] for m in pa.messages]
    np.testing.assert_array_equal(pb.log_time_ns, pa.log_time_ns)
    assert b.metadata["replay"]["diverges_at_s"] == ""
    assert b.metadata["run"]["replay_of"] == str(run)


def test_the_f_t_samples_of_each_cycle_are_the_ones_the_loop_got(run: Path) -> None:
    rec = load(run)
    inputs = Inputs(rec)
    counts = np.array([len(inputs.ft(i)) for i in range(len(inputs))])
    np.testing.assert_array_equal(counts, rec.topic("/estimator/state")["n_samples"])
    # robot clock: the samples of a cycle are not later than the cycle's state
    for i in (1, len(inputs) // 2, len(inputs) - 1):
        assert inputs.ft(i).time_ns[-1] <= inputs.state(i).time_ns


def test_changed_k_yp_changes_the_commands_on_y_only(run: Path, changed: Path) -> None:
    a, b = load(run), load(changed)
    result = diff(a, b)
    assert not result.ok
    differing = {(t.topic, f.column) for t in result.topics for f in t.fields}
    assert differing == {("/control/command", "wrench_1"),
                         ("/control/command", "applied_wrench_1"),
                         ("/control/terms", "ri_1"), ("/control/terms", "total_1")}
    # open loop the measured wrench is the same, so the RI term scales with k_yp: 0.5 / 0.2
    ri_a, ri_b = a.topic("/control/terms")["ri"][:, 1], b.topic("/control/terms")["ri"][:, 1]
    np.testing.assert_allclose(ri_b, 2.5 * ri_a, rtol=1e-12, atol=1e-15)
    # where the replay says its commands leave the recorded ones is where diff sees it
    first = min(f.first_s for t in result.topics for f in t.fields
                if t.topic == "/control/command")
    md = b.metadata["replay"]
    assert float(md["diverges_at_s"]) == pytest.approx(first, abs=1e-9)
    assert md["diverges_on"] == "/control/command wrench_1"
    # ...in ALIGN, at the first cycle with a lateral force
    terms = a.topic("/control/terms")
    t_s = (terms.log_time_ns - a.run_start_ns) / 1e9
    lateral = (terms["phase"] == int(Phase.ALIGN)) & (np.abs(ri_a) > 1e-9)
    assert first == pytest.approx(t_s[np.argmax(lateral)], abs=1e-9)
    events = [m["message"] for m in b.json["/events"].messages if m["name"] == "replay"]
    assert any("not valid after it" in e for e in events)


def test_diff_cli_exit_codes_and_figure(run: Path, same: Path, changed: Path,
                                        tmp_path: Path) -> None:
    ok = runner.invoke(app, ["diff", str(run), str(same)])
    assert ok.exit_code == 0, ok.output
    assert "within tolerance" in ok.stdout
    bad = runner.invoke(app, ["diff", str(run), str(changed), "--plots", str(tmp_path)])
    assert bad.exit_code == 1, bad.output
    assert "first difference: /control/terms ri_1" in bad.stdout
    assert sorted(p.suffix for p in tmp_path.iterdir()) == [".png", ".svg"]
    # no figure unless asked for one
    before = sorted(changed.parent.iterdir())
    quiet = runner.invoke(app, ["diff", str(run), str(changed)])
    assert quiet.exit_code == 1 and "figure:" not in quiet.stdout
    assert sorted(changed.parent.iterdir()) == before
    # one topic asked for, within a tolerance wider than the change
    wide = runner.invoke(app, ["diff", str(run), str(changed), "--topic", "/control/command",
                               "--atol", "1.0"])
    assert wide.exit_code == 0, wide.output


def test_replay_as_a_subprocess_says_where_commands_diverge(run: Path, tmp_path: Path) -> None:
    out = tmp_path / "sub.mcap"
    done = subprocess.run(
        [sys.executable, "-m", "ffexp", "replay", str(run), "--protocol", str(PROTOCOL),
         "--set", K_RI_CHANGED, "--out", str(out)],
        capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "commands differ from the recorded ones from t = " in done.stdout
    assert "/control/command wrench_1" in done.stdout
    assert out.is_file()


@pytest.mark.parametrize("fmt", ["parquet", "csv"])
def test_export_reads_back_with_the_values_load_gives(run: Path, tmp_path: Path,
                                                      fmt: str) -> None:
    result = runner.invoke(app, ["export", str(run), "--format", fmt, "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    rec = load(run)
    names = {p.name for p in tmp_path.iterdir()}
    assert names == {f"{t.strip('/').replace('/', '_')}.{fmt}"
                     for t in [*rec.topics, *rec.json]} | {"recording.json"}
    for topic in ("/estimator/state", "/robot/state", "/ft/raw"):
        path = tmp_path / f"{topic.strip('/').replace('/', '_')}.{fmt}"
        table = (pd.read_parquet(path) if fmt == "parquet"
                 else pd.read_csv(path))
        data = rec.topic(topic)
        # time from the run start: the first cycle is 0
        np.testing.assert_array_equal(table["log_time_ns"], data.log_time_ns)
        np.testing.assert_array_equal(table["t_s"],
                                      (data.log_time_ns - rec.run_start_ns) / 1e9)
        fields = {f.name: f for f in CDR_TOPICS[topic].spec.fields}
        for name, values in data.fields.items():
            flat = values.reshape(len(data), -1)
            f = fields[name]
            cols = element_names(name, f.count, f.unit)
            np.testing.assert_array_equal(table[cols].to_numpy(), flat,
                                          err_msg=f"{fmt} {topic}.{name}")
        frame = rec.frame(topic)  # the same values under the frame's name_k columns
        frame.columns = list(table.columns)
        pd.testing.assert_frame_equal(table, frame, check_dtype=fmt == "parquet")
    est = pd.read_parquet(tmp_path / "estimator_state.parquet") if fmt == "parquet" else \
        pd.read_csv(tmp_path / "estimator_state.csv")
    assert list(est.columns[2:8]) == ["wrench_fx_n", "wrench_fy_n", "wrench_fz_n",
                                      "wrench_tx_nm", "wrench_ty_nm", "wrench_tz_nm"]
    assert "f_z_n" in est and "n_samples" in est
    assert rec.frame("/robot/state")["t_s"].iloc[0] == 0.0


def test_import_ffexp_gives_recording_frames_lazily(run: Path) -> None:
    code = (
        "import sys, ffexp\n"
        "assert 'ffexp.recording' not in sys.modules and 'numpy' not in sys.modules\n"
        f"df = ffexp.recording.load({str(run)!r}).frame('/estimator/state')\n"
        "print(len(df), df.columns[2])\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 0, done.stderr
    n, first = done.stdout.split()
    assert int(n) == len(load(run, ["/estimator/state"]).topic("/estimator/state"))
    assert first == "wrench_0"


@pytest.mark.parametrize(("name", "count", "unit", "names"), [
    ("wrench", 6, "N, N m", ["wrench_fx_n", "wrench_fy_n", "wrench_fz_n", "wrench_tx_nm",
                             "wrench_ty_nm", "wrench_tz_nm"]),
    ("twist", 6, "m/s, rad/s", ["twist_vx_mps", "twist_vy_mps", "twist_vz_mps",
                                "twist_wx_radps", "twist_wy_radps", "twist_wz_radps"]),
    ("stiffness", 6, "N/m, N m/rad", ["stiffness_x_npm", "stiffness_y_npm", "stiffness_z_npm",
                                      "stiffness_rx_nmprad", "stiffness_ry_nmprad",
                                      "stiffness_rz_nmprad"]),
    ("damping", 6, "", ["damping_x", "damping_y", "damping_z", "damping_rx", "damping_ry",
                        "damping_rz"]),
    ("jnt_pos", 7, "rad", [f"jnt_pos_j{k}_rad" for k in range(1, 8)]),
    ("f_z", 1, "N", ["f_z_n"]), ("cycle_s", 1, "s", ["cycle_s"]), ("seq", 1, "", ["seq"]),
    ("target_twist", 3, "m/s, rad/s", ["target_twist_0", "target_twist_1", "target_twist_2"]),
    ("mass_matrix", 49, "kg m^2", [f"mass_matrix_{k}_kgm2" for k in range(49)]),
])
def test_element_names_from_count_and_unit(name: str, count: int, unit: str,
                                           names: list[str]) -> None:
    assert element_names(name, count, unit) == names


def test_a_pose_names_its_translation_and_every_registry_topic_gets_unique_names() -> None:
    pose = element_names("pose", 16, "m")
    assert [pose[3], pose[7], pose[11]] == ["pose_x_m", "pose_y_m", "pose_z_m"]
    assert pose[0] == "pose_r00" and pose[15] == "pose_r33" and len(set(pose)) == 16
    for topic, t in CDR_TOPICS.items():
        cols = [c for f in t.spec.fields for c in
                ([f.name] if f.count == 1 else [f"{f.name}_{k}" for k in range(f.count)])]
        renamed = column_names(topic, ["t_s", "log_time_ns", *cols])
        assert len(renamed) == len(cols), topic  # every field named, none colliding
        assert len(set(renamed.values())) == len(cols), topic


def test_replay_says_the_verdict_it_computed_not_the_recorded_one(run: Path, tmp_path: Path
                                                                   ) -> None:
    """Through another method the commands diverge: the task's end in the replay judged
    the recorded world, so the verdict printed (and analysed) is unknown; through the
    recorded protocol the commands agree and the end is the replay's own."""
    other = runner.invoke(app, ["replay", str(run), "--protocol",
                                str(ROOT / "protocols/method3_impedance.toml"),
                                "--out", str(tmp_path / "other.mcap")])
    assert other.exit_code == 0, other.output
    line = next(x for x in other.stdout.splitlines() if x.startswith("replayed run: "))
    assert line.startswith("replayed run: unknown: the commands differ from t = "), line
    assert metrics(load(tmp_path / "other.mcap")).verdict == "unknown"
    same = runner.invoke(app, ["replay", str(run), "--out", str(tmp_path / "same.mcap")])
    line = next(x for x in same.stdout.splitlines() if x.startswith("replayed run: "))
    assert line.startswith("replayed run: DONE ") or line.startswith("replayed run: ABORT ")
    assert "the commands are the recorded ones up to it" in line
    assert metrics(load(tmp_path / "same.mcap")).verdict != "unknown"


def test_the_recorded_protocol_takes_scene_keys_as_a_run_protocol_does(run: Path) -> None:
    """``--set scene.KEY=V`` on a replay without ``--protocol`` reaches the protocol's
    ``[scene] set`` as ``ffexp run`` takes it (it answered ``scene.target: unknown key``)."""
    from ffexp.protocol import load_run_protocol
    from ffexp.replay import recorded_protocol

    form = "scene.target.lateral=0.02"
    recorded = recorded_protocol(load(run, []), [form, "run.timeout_s=3"])
    as_run = load_run_protocol(PROTOCOL, ["run.timeout_s=4.2", form])
    assert recorded.scene.set[-1] == as_run.scene.set[-1] == "target.lateral=0.02"
    assert recorded.run.timeout_s == 3.0
    # and one element of a list, as a run protocol's --set takes it
    one = recorded_protocol(load(run, []), ["align.k_ri[1]=0.4"])
    assert one.align.k_ri == load_run_protocol(PROTOCOL, ["align.k_ri[1]=0.4"]).align.k_ri
    assert one.align.k_ri[1] == 0.4
