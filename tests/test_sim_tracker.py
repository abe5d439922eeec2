"""The sim tracker's camera model (rate, latency, dropout, noise) on a stand-in world, and
``ffexp calibrate-camera`` through the CLI."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from typer.testing import CliRunner

from drivers.description.scene import Scene
from drivers.sim.tracker import SimTracker
from drivers.vision import load_calibration
from ffexp.cli import app

MS = 1_000_000


class StandIn:
    """A world whose target moves along x at 0.1 m/s (only what the tracker reads)."""

    def __init__(self) -> None:
        self.t_ns = 0
        self.scene = Scene()  # the air bed: the camera's noise is planar
        self.chaser = None  # a fixed base: the world's frame is the arm's

    def target_frames(self) -> tuple[np.ndarray, np.ndarray]:
        target = np.eye(4)
        target[0, 3] = 0.1 * self.t_ns / 1e9
        mouth = target.copy()
        mouth[0, 3] -= 0.125
        return target, mouth


def collect(tracker: SimTracker, world: StandIn, seconds: float) -> list:  # type: ignore[type-arg]
    out = []
    tracker.start()
    for k in range(round(seconds / 0.005)):
        world.t_ns = k * 5 * MS
        obs = tracker.latest()
        assert obs is not None
        out.append((world.t_ns, obs))
    return out


def test_frames_come_at_the_rate_and_arrive_after_the_latency() -> None:
    world = StandIn()
    tracker = SimTracker(world, lambda: world.t_ns, rate_hz=50.0, latency_s=0.03,  # type: ignore[arg-type]
                         position_noise_m=0.0, yaw_noise_deg=0.0, dropout=0.0)
    seen = collect(tracker, world, 1.0)
    assert not seen[0][1].valid  # before the first frame arrives
    valid = [(t, o) for t, o in seen if o.valid]
    assert all(t - o.time_ns >= 30 * MS for t, o in valid)  # never earlier than the latency
    assert max(t - o.time_ns for t, o in valid) < 30 * MS + 20 * MS  # nor older than a period
    frames = {o.frames for _, o in valid}
    assert len(frames) == 49  # 50 frames exposed in 1 s, the last still in flight
    for _, o in valid:  # the pose at exposure, the mouth carried with it
        assert o.pose_m[0, 3] == np.float64(0.1 * o.time_ns / 1e9)
        assert math.isclose(o.mouth_m[0, 3], o.pose_m[0, 3] - 0.125)


def test_dropout_and_noise_match_their_settings() -> None:
    world = StandIn()
    tracker = SimTracker(world, lambda: world.t_ns, rate_hz=200.0, latency_s=0.0,  # type: ignore[arg-type]
                         position_noise_m=0.001, yaw_noise_deg=0.5, dropout=0.3, seed=4)
    seen = collect(tracker, world, 20.0)
    by_frame = {o.frames: o for _, o in seen}
    lost = sum(not o.valid for o in by_frame.values()) / len(by_frame)
    assert abs(lost - 0.3) < 0.03  # 4000 frames: 3 sigma of a binomial is 0.022
    err = np.array([o.pose_m[1, 3] for o in by_frame.values() if o.valid])
    yaw = np.degrees([math.atan2(o.pose_m[1, 0], o.pose_m[0, 0])
                      for o in by_frame.values() if o.valid])
    assert abs(err.std() - 0.001) < 0.0001
    assert abs(yaw.std() - 0.5) < 0.05


def test_calibrate_camera_writes_a_file_the_tracker_reads(tmp_path: Path) -> None:
    pts = tmp_path / "points.csv"
    # a top view at 1000 px/m centred on (0.8, 0): u = 639.5 - 1000 y, v = 359.5 - 1000 (x - 0.8)
    rows = [(0.9, 0.3), (0.9, -0.2), (0.6, -0.2), (0.6, 0.3), (0.75, 0.05)]
    pts.write_text("u,v,x,y\n" + "".join(
        f"{639.5 - 1000 * y},{359.5 - 1000 * (x - 0.8)},{x},{y}\n" for x, y in rows))
    out = tmp_path / "cal.toml"
    res = CliRunner().invoke(app, ["calibrate-camera", str(pts), str(out), "--plane-z-m", "0.05"])
    assert res.exit_code == 0, res.output
    cal = load_calibration(out, "test")
    np.testing.assert_allclose(cal.to_plane(np.array([[639.5, 359.5]])), [[0.8, 0.0]], rtol=0,
                               atol=1e-6)
    pts.write_text("1,2,3,4\n")
    res = CliRunner().invoke(app, ["calibrate-camera", str(pts), str(out)])
    assert res.exit_code == 2 and "at least four" in res.output


def test_a_run_with_the_sim_tracker_records_its_poses_and_who_judged(tmp_path: Path) -> None:
    from ffexp.analysis import metrics
    from ffexp.experiment import run_file
    from ffexp.recording import load
    from ffexp.rig_choice import RigChoice

    root = Path(__file__).resolve().parents[1]
    res = run_file(root / "protocols" / "method1_case1.toml",
                   ["run.timeout_s=2.0", "alignment.source='tracker'"],
                   rig=RigChoice(overrides=("tracker.type='sim'", "tracker.rate_hz=50.0")),
                   out_dir=tmp_path)
    rec = load(res.path)
    poses = rec.topic("/target/pose")
    duration_s = metrics(rec).duration_s
    assert abs(len(poses) - 50 * duration_s) <= 3  # one message per new frame
    assert (poses["valid"][1:] == 1).all() and (poses["age_s"][1:] >= 0.03 - 1e-9).all()
    tf = [m for m in rec.json["/tf"].messages if m["child_frame_id"] == "target_tracked"]
    assert len(tf) == int(poses["valid"].sum())
    verdicts = rec.json["/alignment/verdict"].messages
    assert verdicts[0]["source"] == "tracker" and not verdicts[0]["final"]
    assert verdicts[-1]["final"] and verdicts[-1]["label"] == "not aligned"
    assert verdicts[-1]["truth"] == "not aligned"  # the truth beside the tracker's verdict
    assert rec.metadata["run"]["tracker"] == "sim"
