"""The emulated rig as one object: world, emulated KRC, Net F/T box and camera, served.

:class:`EmulatedRig` assembles what ``ffexp emulate`` serves from an
:class:`EmulatedRigSettings`: the simulated world of a scene, the KRC that
serves it over FRI 1.x (:class:`~drivers.emulate.fri_server.FriEmulator`, with
its pacing and injected faults), optionally the Net F/T box
(:class:`~drivers.emulate.netft_box.NetFtServer`) and the camera above the bed
(:class:`~drivers.emulate.camera_stream.CameraStream`). As a context manager it
opens them all on entry (closing what it opened if one fails) and closes them
on exit; :meth:`EmulatedRig.serve` runs the KRC in its own thread until the
duration of simulated time, a stop request or an error, and re-raises the error
in the caller's thread::

    with EmulatedRig(settings) as rig:
        print(rig.ready_line())
        rig.serve(stop_requested, on_status=print)
    print(rig.summary())

Errors name the caller's fields (``settings.fields``: the command line's options
for ``ffexp emulate``). The robot served is the LWR4+ on a KRC2 LR over FRI, or
with ``robot = "ur5e"`` the UR5e of a UR scene over RTDE on ``listen`` (127.0.0.1:30004
by default; :class:`~drivers.emulate.ur_server.UrEmulator`; its wrench goes over
RTDE, so no Net F/T box, and its faults are :class:`~drivers.emulate.rtde_server.RtdeFaults`:
``faults.loss`` and ``faults.delay_s`` of the output packages, ``ur_disconnect_after``).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Literal

from drivers.description.scene import Scene
from drivers.emulate.camera_stream import CameraStream
from drivers.emulate.faults import FaultSettings
from drivers.emulate.fri_server import EmulatorSettings, EmulatorStats, FriEmulator
from drivers.emulate.netft_box import NetFtServer
from drivers.emulate.robots import ROBOTS
from drivers.emulate.rtde_server import RtdeFaults
from drivers.emulate.ur_server import UrEmulator
from drivers.errors import ConfigError, NotConnectedError
from drivers.sim.world import SimWorld

__all__ = ["EmulatedRig", "EmulatedRigSettings", "SettingNames"]

#: How often :meth:`EmulatedRig.serve` reports the link's state [s of wall time].
STATUS_PERIOD_S = 5.0
#: How often the serving caller checks for a stop request [s].
_POLL_S = 0.1


@dataclass(frozen=True)
class SettingNames:
    """How errors name the settings (the command line's options by default)."""

    port: str = "--port"
    netft_port: str = "--netft-port"
    camera_port: str = "--camera-port"
    camera_calibration: str = "--camera-calibration"
    listen: str = "--listen"
    robot: str = "--robot"


@dataclass(frozen=True)
class EmulatedRigSettings:
    """What the emulated rig serves and how.

    Args:
        scene: the rig to simulate.
        remote: the remote driver's address (``FRIHOST``, ``FRISOCK`` on a KRC).
        seed: the world's seed (None: the scene's).
        port: local UDP port the KRC sends from (0: any).
        pacing: ``realtime`` (wall clock) or ``lockstep`` (a step on each answer).
        lockstep_timeout_s: lockstep: wait this long for a command before a miss.
        faults: injected network faults.
        netft_port: UDP port of the emulated Net F/T box (0: any; None: no box).
        camera_port: TCP port of the MJPEG camera above the bed (0: any; None: no camera).
        camera_fps: the camera's frame rate.
        camera_calibration: where to write the camera's calibration file (None: nowhere).
        duration_s: stop after this much simulated time (0: until stopped).
        host: local address every server binds to.
        fields: how errors name these settings.
        robot: a name of :data:`drivers.emulate.robots.ROBOTS`: ``lwr4`` (a KRC2 LR over
            FRI) or ``ur5e`` (a UR controller over RTDE; the scene's arm must be the UR5e).
        listen: a robot whose link the client opens (RTDE): where its server listens
            (any loopback address may be chosen; None: the robot's default).
        ur_disconnect_after: ``ur5e``: close a client's connection after this many data
            packages (0: never).
    """

    scene: Scene
    remote: tuple[str, int] | None = None
    seed: int | None = None
    port: int = 0
    pacing: Literal["realtime", "lockstep"] = "realtime"
    lockstep_timeout_s: float = 1.0
    faults: FaultSettings = field(default_factory=FaultSettings)
    netft_port: int | None = 49152
    camera_port: int | None = None
    camera_fps: float = 50.0
    camera_calibration: Path | None = None
    duration_s: float = 0.0
    host: str = "0.0.0.0"
    fields: SettingNames = field(default_factory=SettingNames)
    robot: str = "lwr4"
    listen: tuple[str, int] | None = None
    ur_disconnect_after: int = 0

    @property
    def max_cycles(self) -> int | None:
        """World steps in ``duration_s`` (None: no limit)."""
        return round(self.duration_s / self.scene.fri.cycle) if self.duration_s > 0 else None


class EmulatedRig:
    """The emulated rig of ``settings`` (module docstring). Open it with ``with``."""

    def __init__(self, settings: EmulatedRigSettings) -> None:
        self.settings = settings
        self.world: SimWorld | None = None
        """The world as opened (a UR's later sessions run a fresh one: ``ur.world``)."""
        self.robot: FriEmulator | None = None
        self.ur: UrEmulator | None = None
        self.netft: NetFtServer | None = None
        self.camera: CameraStream | None = None
        self._thread: threading.Thread | None = None
        self._failure: BaseException | None = None
        self._last_status = 0.0
        self._stats: EmulatorStats | None = None
        self._ur_summary: str | None = None

    # ------------------------------------------------------------ lifecycle
    def __enter__(self) -> EmulatedRig:
        self.open()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def open(self) -> None:
        """Build the world and open every server (what opened is closed if one fails)."""
        s = self.settings
        if s.robot not in ROBOTS:
            raise ConfigError(s.fields.robot, s.robot,
                              f"choose one of {', '.join(ROBOTS)}")
        if s.scene.arm.model != s.robot:
            raise ConfigError(s.fields.robot, s.robot, f"the scene ({s.scene.name}) has "
                              f"arm.model {s.scene.arm.model!r}, not {s.robot!r}")
        self.world = world = SimWorld(s.scene, seed=s.seed)
        if ROBOTS[s.robot].link == "rtde":
            self._open_ur(world)
            return
        try:
            if s.netft_port is not None:
                self.netft = NetFtServer.open(s.host, s.netft_port, on_bias=world.tare_ft,
                                              field=s.fields.netft_port)
            self.robot = self._open_robot(world)
            if s.camera_port is not None:
                self.camera = CameraStream(world, s.host, s.camera_port, fps=s.camera_fps,
                                           field=s.fields.camera_port)
                if s.camera_calibration is not None:
                    self._write_calibration(self.camera, s.camera_calibration)
        except BaseException:
            self.close()
            raise

    def _open_ur(self, world: SimWorld) -> None:
        """The UR controller's RTDE server (the scene's arm must be a UR)."""
        s = self.settings
        faults = RtdeFaults(loss=s.faults.loss, delay_s=s.faults.delay_s,
                            disconnect_after=s.ur_disconnect_after, seed=s.faults.seed)
        host, port = s.listen or ROBOTS[s.robot].listen or ("127.0.0.1", 30004)
        self.ur = UrEmulator(world, host, port, pacing=s.pacing,
                             lockstep_timeout_s=s.lockstep_timeout_s, faults=faults,
                             where=s.fields.listen).start()

    def _open_robot(self, world: SimWorld) -> FriEmulator:
        """The robot controller's server: a KRC2 LR over FRI 1.x (it closes the Net F/T box
        with itself)."""
        s = self.settings
        if s.remote is None:
            raise ConfigError("--remote", "", "the remote driver's address is required")
        return FriEmulator(
            world,
            EmulatorSettings(
                remote=s.remote,
                port=s.port,
                port_field=s.fields.port,
                bind_host=s.host,
                pacing=s.pacing,
                lockstep_timeout_s=s.lockstep_timeout_s,
                faults=s.faults,
            ),
            self.netft,
        )

    def _write_calibration(self, camera: CameraStream, path: Path) -> None:
        try:
            camera.write_calibration(path)
        except OSError as exc:
            raise ConfigError(self.settings.fields.camera_calibration, str(path),
                              exc.strerror or str(exc)) from None

    def stop(self) -> None:
        """Ask the KRC to stop after its current cycle (thread-safe)."""
        if self.ur is not None:
            self.ur.stop()
        if self.robot is not None:
            self.robot.stop()

    def close(self) -> None:
        """Stop serving and close every server (idempotent)."""
        ur, self.ur = self.ur, None
        if ur is not None:
            ur.close()
            self._ur_summary = ur.summary()
        robot, self.robot = self.robot, None
        if robot is not None:
            robot.stop()
            if self._thread is not None and self._thread.is_alive():
                self._thread.join(5.0)
            robot.close()  # closes the Net F/T box too
            self._stats = robot.stats
            self._stats.state, self._stats.quality = robot.state, robot.quality
        elif self.netft is not None:
            self.netft.close()
        self.netft = None
        camera, self.camera = self.camera, None
        if camera is not None:
            camera.close()

    # ------------------------------------------------------------ serving
    def ready_line(self) -> str:
        """One line: where the KRC serves, to whom, the Net F/T box and camera, cycle, pacing."""
        s = self.settings
        if self.ur is not None:
            host, port = self.ur.address
            return (f"UR5e controller (RTDE) on {host}:{port}, cycle "
                    f"{s.scene.fri.cycle * 1000.0:g} ms, {s.pacing}")
        robot = self._require()
        host, lport = robot.address
        ft = f"Net F/T on {s.host}:{self.netft.address[1]}" if self.netft is not None \
            else "no Net F/T"
        if self.camera is not None:
            ft += (f", camera on http://{s.host}:{self.camera.port}/stream.mjpg at "
                   f"{s.camera_fps:g} fps")
        cycle_ms = round(s.scene.fri.cycle * 1000.0)
        remote = "?" if s.remote is None else f"{s.remote[0]}:{s.remote[1]}"
        return (f"KRC on {host}:{lport} -> remote {remote}, {ft}, "
                f"cycle {cycle_ms} ms, {s.pacing}")

    def serve(self, stop_requested: Callable[[], bool],
              on_status: Callable[[str], None] | None = None) -> EmulatorStats | None:
        """Serve in a thread of its own (started here: it inherits the caller's scheduling)
        until ``duration_s``, ``stop_requested()`` (polled every 0.1 s) or an error, which is
        re-raised here. ``on_status`` gets a status line every :data:`STATUS_PERIOD_S`.
        Returns the KRC's counters (``None`` for a UR: :meth:`summary`)."""
        if self.ur is not None:
            self._serve_ur(self.ur, stop_requested, on_status)
            return None
        robot = self._require()
        self._last_status = time.monotonic()

        def on_cycle(emu: FriEmulator) -> None:
            if self.camera is not None:  # the camera sees the world between steps, never during
                self.camera.publish()
            now = time.monotonic()
            if on_status is not None and now - self._last_status >= STATUS_PERIOD_S:
                self._last_status = now
                st = emu.stats
                on_status(f"t={emu.world.time:7.2f} s  {emu.state.name} {emu.quality.name}  "
                          f"answered {st.answered} missed {st.missed} applied {st.applied}")

        def run() -> None:
            try:
                robot.run(max_cycles=self.settings.max_cycles, on_cycle=on_cycle)
            except BaseException as exc:  # re-raised below, in the caller's thread
                self._failure = exc

        self._thread = thread = threading.Thread(target=run, name="fri-emulator", daemon=True)
        thread.start()
        # lockstep steps the world on answers: with no remote answering, no simulated time
        # passes, so --duration also ends the wait for a first answer after as much wall time
        alone_until = (time.monotonic() + self.settings.duration_s
                       if self.settings.duration_s > 0 else None)
        while thread.is_alive():
            if stop_requested() or (alone_until is not None and robot.stats.answered == 0
                                    and time.monotonic() >= alone_until):
                robot.stop()
            thread.join(_POLL_S)
        if self._failure is not None:
            raise self._failure
        return robot.stats

    def _serve_ur(self, ur: UrEmulator, stop_requested: Callable[[], bool],
                  on_status: Callable[[str], None] | None) -> None:
        self._last_status = time.monotonic()

        def on_cycle(emu: UrEmulator) -> None:
            if stop_requested():
                emu.stop()
            now = time.monotonic()
            if on_status is not None and now - self._last_status >= STATUS_PERIOD_S:
                self._last_status = now
                on_status(emu.status())

        # --duration also bounds the wall time without a client: then the world never steps
        wall = self.settings.duration_s if self.settings.duration_s > 0 else None
        ur.run(max_cycles=self.settings.max_cycles, on_cycle=on_cycle, max_wall_s=wall)

    def summary(self) -> str:
        """The KRC's counters in one line, with its last state and quality."""
        if self.ur is not None:
            return self.ur.summary()
        if self._ur_summary is not None:
            return self._ur_summary
        robot = self.robot
        if robot is not None:
            stats = robot.stats
            stats.state, stats.quality = robot.state, robot.quality
            return stats.summary()
        if self._stats is None:
            raise NotConnectedError("the emulated rig was never opened")
        return self._stats.summary()

    def _require(self) -> FriEmulator:
        if self.robot is None:
            raise NotConnectedError("the emulated rig is not open (use it as a context manager)")
        return self.robot
