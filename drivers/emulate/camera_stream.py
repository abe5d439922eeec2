"""The emulator's camera: the simulated target rendered from above, served as MJPEG over HTTP.

``GET /stream.mjpg`` answers ``multipart/x-mixed-replace`` with one JPEG per
frame at the camera's rate (what IP cameras serve; OpenCV reads it as a
capture source), ``GET /calibration.toml`` the camera's calibration (the
top view's pixels-to-plane homography, :mod:`drivers.vision.calibration`).
The emulator's thread hands over the target's pose after each cycle
(:meth:`CameraStream.publish`: a copy under a lock, so the render thread
never reads the world while it steps); a render thread takes the newest at
``fps`` on the wall clock (the emulator runs the world at real time) and
renders it
(:class:`drivers.world.render.TargetRenderer`); each client's thread sends the
newest frame once. Everything stops with :meth:`CameraStream.close`.
"""

from __future__ import annotations

import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from drivers.base.types import F64
from drivers.errors import AddressError
from drivers.vision.calibration import save_calibration
from drivers.world.render import TargetRenderer, top_view
from drivers.world.world import SimWorld

__all__ = ["CameraStream"]

_BOUNDARY = b"ffexpframe"


class CameraStream:
    """A synthetic camera above the simulated bed, served over HTTP.

    Args:
        world: the emulated rig (its target is rendered).
        host, port: where to listen (port 0: any free port; see :attr:`port`).
        fps: frames per second.
        size_px: ``(width, height)``; ``px_per_m``: image scale on the target's top face.
        marker_dictionary, marker_id, marker_m: the marker on the target's top face centre.
        jpeg_quality: JPEG quality (1..100).
        field: names the option in errors (``--camera-port``).
    """

    def __init__(self, world: SimWorld, host: str = "0.0.0.0", port: int = 8080, *,
                 fps: float = 50.0, size_px: tuple[int, int] = (1280, 720),
                 px_per_m: float = 1000.0, marker_dictionary: str = "DICT_4X4_50",
                 marker_id: int = 0, marker_m: float = 0.12, jpeg_quality: int = 90,
                 noise: float = 1.0, field: str = "camera port") -> None:
        self.world = world
        self.period_s = 1.0 / fps
        target, _ = world.target_frames()
        size = world.scene.target.size
        self.plane_z_m = float(target[2, 3] + size[2] / 2.0)
        self.plane_to_px: F64 = top_view((float(target[0, 3]), float(target[1, 3])), px_per_m,
                                         size_px)
        self.renderer = TargetRenderer(self.plane_to_px, size_px, (size[0], size[1]),
                                       marker_dictionary, marker_id, marker_m, noise=noise,
                                       seed=world.seed)
        self.jpeg_quality = jpeg_quality
        self._pose_lock = threading.Lock()
        self._target: F64 = target  # the newest published target pose (world frame)
        self._cond = threading.Condition()
        self._jpeg = b""
        self._seq = 0
        self._stop = threading.Event()
        self.frames = 0
        stream = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, format: str, *args: Any) -> None:
                return

            def do_GET(self) -> None:
                if self.path.startswith("/calibration.toml"):
                    body = stream.calibration_text().encode()
                    self.send_response(200)
                    self.send_header("Content-Type", "application/toml")
                    self.send_header("Content-Length", str(len(body)))
                    self.end_headers()
                    self.wfile.write(body)
                    return
                if not self.path.startswith("/stream.mjpg"):
                    self.send_error(404, "try /stream.mjpg or /calibration.toml")
                    return
                self.send_response(200)
                self.send_header("Content-Type",
                                 f"multipart/x-mixed-replace; boundary={_BOUNDARY.decode()}")
                self.send_header("Cache-Control", "no-cache")
                self.end_headers()
                stream._serve(self)

        try:
            self.server = ThreadingHTTPServer((host, port), Handler)
        except OSError as exc:
            raise AddressError(field, f"{host}:{port}", exc.strerror or str(exc)) from None
        self.server.daemon_threads = True
        self.port = int(self.server.server_address[1])
        self._threads = [threading.Thread(target=self.server.serve_forever, name="camera-http",
                                          daemon=True),
                         threading.Thread(target=self._render_loop, name="camera-render",
                                          daemon=True)]
        for t in self._threads:
            t.start()

    def calibration_text(self) -> str:
        """The calibration file of this camera (pixels to the target's top face)."""
        import tempfile

        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "c.toml"
            self.write_calibration(path)
            return path.read_text()

    def write_calibration(self, path: Path) -> None:
        save_calibration(path, np.asarray(np.linalg.inv(self.plane_to_px), np.float64),
                         self.plane_z_m,
                         "ffexp emulate's synthetic camera: pixels -> base-frame metres on the "
                         "target's top face")

    def publish(self) -> None:
        """Take the world's target pose now; call it from the thread that steps the world,
        between steps (the emulator's ``on_cycle``)."""
        target, _ = self.world.target_frames()  # new arrays
        with self._pose_lock:
            self._target = target

    def _render_loop(self) -> None:
        next_t = time.monotonic()
        while not self._stop.is_set():
            with self._pose_lock:
                target = self._target
            frame = self.renderer.render(target)
            ok, buf = cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, self.jpeg_quality])
            if ok:
                with self._cond:
                    self._jpeg = buf.tobytes()
                    self._seq += 1
                    self.frames += 1
                    self._cond.notify_all()
            next_t += self.period_s
            delay = next_t - time.monotonic()
            if delay < 0:  # behind: skip frames rather than drift
                next_t = time.monotonic()
                delay = 0.0
            self._stop.wait(delay)

    def _serve(self, handler: BaseHTTPRequestHandler) -> None:
        seen = -1
        while not self._stop.is_set():
            with self._cond:
                while self._seq == seen and not self._stop.is_set():
                    self._cond.wait(1.0)
                data, seen = self._jpeg, self._seq
            try:
                handler.wfile.write(b"--" + _BOUNDARY + b"\r\nContent-Type: image/jpeg\r\n"
                                    + f"Content-Length: {len(data)}\r\n\r\n".encode()
                                    + data + b"\r\n")
                handler.wfile.flush()
            except OSError:  # the client went away
                return

    def close(self) -> None:
        """Stop rendering and serving; idempotent."""
        if self._stop.is_set():
            return
        self._stop.set()
        with self._cond:
            self._cond.notify_all()
        self.server.shutdown()
        self.server.server_close()
        for t in self._threads:
            t.join(timeout=5.0)
