"""``ffexp calibrate`` and ``ffexp resimulate``: the mechanism on short simulator recordings
made at parameters set in ``tests/calib_recordings.py`` (the acceptance numbers, on longer
recordings, are benchmarks/bench_calibrate.py's)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from calib_recordings import SCENE, TRUTH, glide, push
from typer.testing import CliRunner

from ffexp.calibrate.inputs import read_input
from ffexp.calibrate.params import FITTABLE
from ffexp.calibrate.resim import base_scene, rollout
from ffexp.calibrate.run import calibrate
from ffexp.cli import app
from ffexp.diff import diff
from ffexp.errors import InputError
from ffexp.recording import load

runner = CliRunner()


@pytest.fixture(scope="module")
def recs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    out = tmp_path_factory.mktemp("calib")
    return {"glide": glide(out / "glide"), "push": push(out / "push"),
            "fri": push(out / "fri", ("robot.wire_precision=true", "ft.type=fri-estimate"))}


def test_replay_in_the_recorded_scene_reproduces_the_arm_exactly(recs: dict[str, Path],
                                                                tmp_path: Path) -> None:
    sim = tmp_path / "sim.mcap"
    result = runner.invoke(app, ["resimulate", str(recs["push"]), "--out", str(sim)])
    assert result.exit_code == 0, result.stderr
    assert f"recording: {sim}" in result.stdout
    # deterministic physics: the recorded commands, replayed open loop, give the same arm
    d = diff(load(recs["push"]), load(sim), ["/robot/state"], rtol=0.0, atol=1e-12)
    assert d.ok, [(f.column, f.max_abs) for t in d.topics for f in t.fields]
    # the F/T differs by the sensor's noise only (the replay's sensor is ideal)
    d = diff(load(recs["push"]), load(sim), ["/ft/raw"], rtol=0.0, atol=0.3)
    assert d.ok


def test_replay_at_other_parameters_parts_where_diff_says(recs: dict[str, Path],
                                                          tmp_path: Path) -> None:
    sim = tmp_path / "sim.mcap"
    result = runner.invoke(app, ["resimulate", str(recs["push"]), "--out", str(sim),
                                 "--scene", str(SCENE)])
    assert result.exit_code == 0, result.stderr
    d = diff(load(recs["push"]), load(sim), ["/robot/state"], rtol=0.0, atol=1e-6)
    assert not d.ok  # the scene's default delay and friction move the arm differently
    assert d.first is not None and d.first.first_s >= 0.5  # not before the robot commands


def test_fri_recording_replays_to_float32(recs: dict[str, Path]) -> None:
    scene = base_scene(SCENE)
    inp = read_input(recs["fri"], scene, tuple(FITTABLE))
    assert inp.wire_precision and inp.ft_type == "fri-estimate"
    truth = [f"{k}={v}" for k, v in TRUTH.items()]
    tr = rollout(inp, SCENE, truth)
    assert tr.failed is None
    assert np.max(np.abs(tr.tcp - inp.tcp)) < 1e-6  # float32 on the wire, nothing more


@pytest.mark.slow
def test_loop_delay_is_recovered_exactly_over_fri(recs: dict[str, Path]) -> None:
    """On a recording made over FRI's float32 wire with the KRC's F/T estimate."""
    which = "fri"
    # the delay trades off against the joints' friction (both slow the arm's response):
    # fitted together, in turns, both come out right
    res, _ = calibrate([recs[which]], ["fri.command_delay_cycles=0:3", "arm.friction_scale"],
                       SCENE, jobs=1)
    delay, scale = res.estimates
    assert delay.value == TRUTH["fri.command_delay_cycles"] != delay.start
    assert delay.identified and delay.ci_lo == delay.ci_hi == delay.value
    assert scale.value == pytest.approx(TRUTH["arm.friction_scale"], rel=0.05)
    assert res.converged


def test_bed_friction_from_a_glide(recs: dict[str, Path]) -> None:
    res, _ = calibrate([recs["glide"]], ["target.mu=0:0.02"], SCENE, jobs=1)
    (est,) = res.estimates
    assert est.start == pytest.approx(0.0085)
    assert est.value == pytest.approx(TRUTH["target.mu"], rel=0.03)
    assert est.identified and est.ci_lo <= est.value <= est.ci_hi
    before, after = res.start["fit"][0].rms["target"], res.final["fit"][0].rms["target"]
    assert after < before / 5


def test_unexcited_parameter_is_bad_input_or_reported_unidentified(
        recs: dict[str, Path]) -> None:
    with pytest.raises(InputError, match=r"no recording excites contact\.restitution"):
        calibrate([recs["glide"]], ["contact.restitution"], SCENE, jobs=1)
    res, _ = calibrate([recs["glide"]], ["contact.restitution"], SCENE, jobs=1,
                       keep_unidentified=True)
    (est,) = res.estimates
    assert not est.identified
    assert (est.ci_lo, est.ci_hi) == (est.lo, est.hi)
    assert est.value == est.start


@pytest.mark.slow
def test_cli_writes_a_scene_with_its_provenance(recs: dict[str, Path], tmp_path: Path) -> None:
    out = tmp_path / "cal.toml"
    result = runner.invoke(app, ["calibrate", str(recs["glide"]), "--fit", "target.mu",
                                 "--holdout", str(recs["push"]), "--out", str(out),
                                 "--jobs", "2"])
    assert result.exit_code == 0, result.stderr
    from drivers.description.scene import load_scene

    scene = load_scene(out)
    assert scene.target.mu == pytest.approx(TRUTH["target.mu"], rel=0.03)
    text = out.read_text()
    assert f"fitted to: {recs['glide']}" in text and f"held out: {recs['push']}" in text
    assert "source revision:" in text and "# calibrated, 95 %" in text
    report = tmp_path / "cal-report"
    assert (report / "calibration.html").read_text().count("<img") == 2  # fitted + held out
    assert (report / "calibration.json").exists()
    page = tmp_path / "page.html"
    result = runner.invoke(app, ["report", str(report), "--out", str(page)])
    assert result.exit_code == 0, result.stderr
    assert "target.mu" in page.read_text()  # the parameter table, through ffexp report


def test_a_fit_that_does_not_converge_writes_no_scene(recs: dict[str, Path], tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    import ffexp.calibrate.fit as fit

    monkeypatch.setattr(fit, "LSQ_MAX_NFEV", 1)
    out = tmp_path / "cal.toml"
    result = runner.invoke(app, ["calibrate", str(recs["glide"]), "--fit", "target.mu",
                                 "--out", str(out), "--jobs", "1"])
    assert result.exit_code == 1
    assert "did not converge" in result.stderr and "no scene written" in result.stderr
    assert not out.exists()


def _truncated(src: Path, dst: Path) -> Path:
    data = src.read_bytes()
    dst.write_bytes(data[: len(data) // 2])
    return dst


def _without(src: Path, dst: Path, topic: str) -> Path:
    from mcap.reader import make_reader
    from mcap.writer import Writer

    with src.open("rb") as fin, dst.open("wb") as fout:
        reader = make_reader(fin)
        w = Writer(fout)
        w.start()
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for meta in reader.iter_metadata():
            w.add_metadata(meta.name, meta.metadata)
        for schema, channel, msg in reader.iter_messages():
            if channel.topic == topic:
                continue
            if schema is not None and schema.id not in schemas:
                schemas[schema.id] = w.register_schema(schema.name, schema.encoding,
                                                       schema.data)
            if channel.id not in channels:
                channels[channel.id] = w.register_channel(
                    channel.topic, channel.message_encoding,
                    schemas.get(schema.id, 0) if schema else 0)
            w.add_message(channels[channel.id], msg.log_time, msg.data, msg.publish_time)
        w.finish()
    return dst


@pytest.mark.parametrize("case", ["not a key", "not fittable", "bounds exclude start",
                                  "empty bounds", "truncated", "no commands", "other scene",
                                  "other robot"])
def test_bad_input_is_one_line_exit_2_nothing_written(recs: dict[str, Path], tmp_path: Path,
                                                      case: str) -> None:
    rec, fit, expect = recs["glide"], "target.mu", ""
    if case == "not a key":
        fit, expect = "target.nope", "'target.nope' is not a scene parameter"
    elif case == "not fittable":
        fit, expect = "target.mass", "cannot be fitted"
    elif case == "bounds exclude start":
        fit, expect = "target.mu=0.009:0.02", "exclude the start value 0.0085"
    elif case == "empty bounds":
        fit, expect = "target.mu=0.01:0.001", "empty bounds"
    elif case == "truncated":
        rec, expect = _truncated(recs["glide"], tmp_path / "cut.mcap"), "incomplete"
    elif case == "no commands":
        rec = _without(recs["glide"], tmp_path / "nocmd.mcap", "/robot/command")
        expect = "no /robot/command"
    elif case == "other scene":
        expect = "recorded in another scene: target.mass"
    elif case == "other robot":
        from ffexp.experiment import run_file
        from ffexp.rig_choice import RigChoice

        rec = run_file(Path(SCENE).parents[2] / "protocols/method2_f08.toml",
                       ["run.timeout_s=0.6"], rig=RigChoice(driver="mock"),
                       out_dir=tmp_path / "mock").path
        expect = "robot driver 'mock'"
    out = tmp_path / "cal.toml"
    args = ["calibrate", str(rec), "--fit", fit, "--out", str(out), "--jobs", "1"]
    if case == "other scene":
        args += ["--scene-set", "target.mass=10.0"]
    result = runner.invoke(app, args)
    assert result.exit_code == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and expect in lines[0], lines
    assert not out.exists() and not (tmp_path / "cal-report").exists()


def test_resimulate_bad_input_writes_nothing(recs: dict[str, Path], tmp_path: Path) -> None:
    rec = _without(recs["glide"], tmp_path / "nocmd.mcap", "/robot/command")
    out = tmp_path / "sim.mcap"
    result = runner.invoke(app, ["resimulate", str(rec), "--out", str(out)])
    assert result.exit_code == 2
    assert result.stderr.strip().count("\n") == 0 and "no /robot/command" in result.stderr
    result = runner.invoke(app, ["resimulate", str(recs["glide"]), "--out",
                                 str(recs["glide"])])
    assert result.exit_code == 2 and "is the recording itself" in result.stderr
    assert not out.exists()


def test_a_resimulation_is_complete_and_not_taken_for_a_run_that_ended_abnormally(
        recs: dict[str, Path], tmp_path: Path) -> None:
    from ffexp.recording.reader import load

    out = tmp_path / "sim.mcap"
    result = runner.invoke(app, ["resimulate", str(recs["glide"]), "--out", str(out)])
    assert result.exit_code == 0, result.stderr
    sim = load(out)
    assert sim.complete and not sim.warnings, sim.warnings
    assert sim.metadata["resimulation"]["resimulated_from"] == str(recs["glide"])
    diff = runner.invoke(app, ["diff", str(recs["glide"]), str(out), "--atol", "0.1"])
    assert diff.exit_code in (0, 1) and "ended abnormally" not in diff.stderr, diff.stderr


def test_torque_loop_r_is_fitted_from_a_scene_that_sets_it() -> None:
    """``arm.torque_loop_r`` is fittable; a base scene that leaves it unset is one clear
    error (no start value), one that sets it starts there."""
    from drivers.config import load_model
    from drivers.description.scene import Scene
    from ffexp.calibrate.params import parse_fit
    from ffexp.errors import ConfigError

    assert "arm.torque_loop_r" in FITTABLE
    unset = base_scene(Path(SCENE), [])
    with pytest.raises(ConfigError, match=r"does not set arm\.torque_loop_r"):
        parse_fit(["arm.torque_loop_r"], unset)
    set_ = base_scene(Path(SCENE), ["arm.torque_loop_r=0.002"])
    (p,) = parse_fit(["arm.torque_loop_r=0:0.01"], set_)
    assert (p.lo, p.hi, p.start) == (0.0, 0.01, 0.002)
    assert load_model(Scene, Path(SCENE)).arm.torque_loop_r is None
