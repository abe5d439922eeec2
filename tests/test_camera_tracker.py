"""The camera tracker: poses from a video rendered from a simulated run (1280x720) and from
the emulator's MJPEG stream over loopback; lost markers and streams; calibration files."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from drivers.camera import CameraTracker
from drivers.camera.backend import CameraTrackerConfig
from drivers.errors import ConfigError
from drivers.vision import Calibration, load_calibration, save_calibration
from drivers.vision.calibration import calibration_from_points, from_extrinsics
from drivers.world.render import TargetRenderer, top_view

SIZE = (1280, 720)


def yaw_of(pose: np.ndarray) -> float:
    return math.degrees(math.atan2(pose[1, 0], pose[0, 0]))


@pytest.fixture(scope="module")
def world():  # type: ignore[no-untyped-def]
    from drivers.description import load_scene
    from drivers.world import SimWorld

    scene = load_scene(Path("data/scenes/paper.toml"),
                       ["target.velocity=[0.03, -0.02, 0.15]", "target.mu=0.0",
                        "target.hose.stiffness=0", "target.hose.damping=0"])  # drifts freely
    return SimWorld(scene, seed=3)


def camera(world, px_per_m: float = 1000.0):  # type: ignore[no-untyped-def]
    target, _ = world.target_frames()
    g = top_view((float(target[0, 3]), float(target[1, 3])), px_per_m, SIZE)
    z = float(target[2, 3] + world.scene.target.size[2] / 2)
    return g, Calibration(np.linalg.inv(g), z)


def test_pose_from_a_video_of_a_simulated_run_is_within_2_mm_and_1_deg(
        world, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    g, cal = camera(world)
    renderer = TargetRenderer(g, SIZE, (0.25, 0.25), noise=2.0, seed=1)
    video = tmp_path / "run.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 50.0, SIZE)
    truth, mouths = [], []
    for _ in range(40):  # 0.8 s at 50 fps: the target drifts and turns
        for _ in range(4):
            world.advance(None)
        target, mouth = world.target_frames()
        truth.append(target)
        mouths.append(mouth)
        writer.write(renderer.render(target))
    writer.release()
    seen = []
    cfg = CameraTrackerConfig(source=str(video), mouth_in_target_m=(-0.125, 0.0, 0.073))
    tracker = CameraTracker(cfg, cal, on_frame=seen.append)
    tracker.start()
    try:
        while True:
            obs = tracker.wait(30.0, valid=False)
            assert obs is not None, "the tracker hung"
            if "end of the source" in obs.status:
                break
    finally:
        tracker.stop()
    poses = [o for o in seen if o.valid]
    assert len(poses) == len(truth)
    moved = np.hypot(*(truth[-1][:2, 3] - truth[0][:2, 3]))
    assert moved > 0.01  # the video shows a moving target
    for obs, t, m in zip(poses, truth, mouths, strict=True):
        assert np.hypot(*(obs.pose_m[:2, 3] - t[:2, 3])) < 0.002
        assert abs(yaw_of(obs.pose_m) - yaw_of(t)) < 1.0
        assert np.hypot(*(obs.mouth_m[:2, 3] - m[:2, 3])) < 0.002  # the funnel mouth too


def test_stream_over_loopback_then_lost_gives_a_status_not_a_hang(world) -> None:  # type: ignore[no-untyped-def]
    from drivers.emulate.camera_stream import CameraStream

    stream = CameraStream(world, "127.0.0.1", 0, fps=50.0)
    try:
        cal_text = stream.calibration_text()
        assert "[homography]" in cal_text
        _, cal = camera(world)
        cfg = CameraTrackerConfig(source=f"http://127.0.0.1:{stream.port}/stream.mjpg",
                                  lost_after_s=0.5, reopen_s=0.2)
        tracker = CameraTracker(cfg, cal)
        tracker.start()
        try:
            obs = tracker.wait(30.0)
            assert obs is not None and obs.valid and obs.source == "camera"
            target, _ = world.target_frames()
            assert np.hypot(*(obs.pose_m[:2, 3] - target[:2, 3])) < 0.002
            assert abs(yaw_of(obs.pose_m) - yaw_of(target)) < 1.0
            stream.close()
            while True:
                lost = tracker.wait(30.0, valid=False)
                assert lost is not None, "the tracker hung"
                if not lost.valid and lost.status.startswith("stream lost"):
                    break
            np.testing.assert_allclose(lost.pose_m, tracker._last_valid.pose_m)  # kept
            assert tracker.latest() is not None
        finally:
            tracker.stop()
    finally:
        stream.close()


def test_a_frame_without_the_marker_is_an_invalid_observation_keeping_the_last_pose(
        world) -> None:  # type: ignore[no-untyped-def]
    g, cal = camera(world)
    target, _ = world.target_frames()
    tracker = CameraTracker(CameraTrackerConfig(), cal)
    good = tracker.process(TargetRenderer(g, SIZE, (0.25, 0.25)).render(target), 1)
    assert good.valid
    blank = tracker.process(np.full((SIZE[1], SIZE[0], 3), 90, np.uint8), 2)
    assert not blank.valid and blank.status == "marker not found"
    np.testing.assert_array_equal(blank.pose_m, good.pose_m)
    assert blank.frames == good.frames + 1


def test_intrinsics_and_extrinsics_give_the_homography_of_the_projection() -> None:
    k = np.array([[900.0, 0.0, 640.0], [0.0, 900.0, 360.0], [0.0, 0.0, 1.0]])
    rvec = np.array([math.pi - 0.05, 0.03, 0.02])
    tvec = np.array([0.1, -0.05, 1.2])
    plane_z = 0.05
    pts = np.array([[0.1, 0.2, plane_z], [-0.2, 0.1, plane_z], [0.3, -0.1, plane_z]])
    px, _ = cv2.projectPoints(pts, rvec, tvec, k, np.zeros(5))
    hom = from_extrinsics(k, rvec, tvec, plane_z)
    back = Calibration(hom, plane_z).to_plane(px.reshape(-1, 2))
    np.testing.assert_allclose(back, pts[:, :2], atol=1e-9)


def test_calibration_file_round_trip_and_errors(tmp_path: Path) -> None:
    px = np.array([[100.0, 100.0], [1100.0, 120.0], [1080.0, 650.0], [120.0, 600.0]])
    plane = np.array([[0.9, 0.3], [0.9, -0.2], [0.6, -0.2], [0.6, 0.3]])
    hom = calibration_from_points(px, plane)
    path = tmp_path / "cal.toml"
    save_calibration(path, hom, 0.05, "test")
    cal = load_calibration(path, "rig.toml: tracker.calibration")
    np.testing.assert_allclose(cal.to_plane(px), plane, atol=1e-9)
    assert cal.plane_z_m == 0.05
    path.write_text("[homography]\nmatrix = [[1, 0], [0, 1]]\n")
    with pytest.raises(ConfigError, match=r"homography\.matrix"):
        load_calibration(path, "rig.toml: tracker.calibration")
    path.write_text("plane_z_m = 0.0\n")
    with pytest.raises(ConfigError, match=r"\[homography\]"):
        load_calibration(path, "rig.toml: tracker.calibration")
    with pytest.raises(ValueError, match="four"):
        calibration_from_points(px[:3], plane[:3])


def test_a_stalled_stream_is_reported_lost_not_waited_for(world) -> None:  # type: ignore[no-untyped-def]
    """A server that sends one frame and then goes silent, keeping the connection open."""
    import threading
    from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

    g, cal = camera(world)
    target, _ = world.target_frames()
    ok, jpeg = cv2.imencode(".jpg", TargetRenderer(g, SIZE, (0.25, 0.25)).render(target))
    assert ok
    release = threading.Event()

    class Stall(BaseHTTPRequestHandler):
        def log_message(self, *args: object) -> None:
            return

        def do_GET(self) -> None:
            self.send_response(200)
            self.send_header("Content-Type", "multipart/x-mixed-replace; boundary=f")
            self.end_headers()
            for _ in range(2):  # FFmpeg's demuxer reads one part ahead
                self.wfile.write(b"--f\r\nContent-Type: image/jpeg\r\nContent-Length: "
                                 + str(len(jpeg)).encode() + b"\r\n\r\n" + jpeg.tobytes()
                                 + b"\r\n")
            self.wfile.flush()
            release.wait(30.0)

    server = ThreadingHTTPServer(("127.0.0.1", 0), Stall)
    server.daemon_threads = True
    threading.Thread(target=server.serve_forever, daemon=True).start()
    cfg = CameraTrackerConfig(source=f"http://127.0.0.1:{server.server_address[1]}/s.mjpg",
                              lost_after_s=0.5, reopen_s=5.0)
    tracker = CameraTracker(cfg, cal)
    tracker.start()
    try:
        assert tracker.wait(30.0) is not None  # the frame it got
        while True:
            lost = tracker.wait(30.0, valid=False)
            assert lost is not None, "the tracker hung on a silent stream"
            if lost.status.startswith("stream lost"):
                break
        assert not lost.valid
    finally:
        release.set()
        tracker.stop()
        server.shutdown()
        server.server_close()


def test_latest_reports_a_silent_capture_itself(world) -> None:  # type: ignore[no-untyped-def]
    import threading

    g, cal = camera(world)
    target, _ = world.target_frames()
    tracker = CameraTracker(CameraTrackerConfig(lost_after_s=0.5), cal)
    assert tracker.process(TargetRenderer(g, SIZE, (0.25, 0.25)).render(target), 1).valid
    tracker._thread = threading.current_thread()  # a capture "running" that never publishes
    try:
        assert tracker.latest() is not None and tracker.latest().valid  # type: ignore[union-attr]
        tracker._published_at -= 10.0  # as if it had been silent for 10 s
        obs = tracker.latest()
        assert obs is not None and not obs.valid
        assert obs.status.startswith("stream lost: no frame for 10.")
        assert tracker.latest() is obs  # said once
    finally:
        tracker._thread = None
