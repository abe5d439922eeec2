"""The emulated rig as one object: world, a family's emulated controller, Net F/T box and camera.

:class:`EmulatedRig` assembles what ``ffexp emulate`` serves from an
:class:`EmulatedRigSettings`: the simulated world of a scene, the robot controller that
serves it (``settings.robot``: a family's :class:`~drivers.base.backend.Emulator`, found
through :mod:`drivers.registry`; what it builds is a
:class:`~drivers.emulate.served.ServedRobot`, e.g. a KRC2 LR over FRI 1.x sending to
``remote``, or a UR controller over RTDE listening on ``listen``), optionally the Net
F/T box (:class:`~drivers.emulate.netft_box.NetFtServer`, for a controller whose entry
asks for one) and the camera above the bed
(:class:`~drivers.emulate.camera_stream.CameraStream`). As a context manager it
opens them all on entry (closing what it opened if one fails) and closes them
on exit; :meth:`EmulatedRig.serve` serves until the duration of simulated time, a stop
request or an error, and re-raises the error in the caller's thread::

    with EmulatedRig(settings) as rig:
        print(rig.ready_line())
        rig.serve(stop_requested, on_status=print)
    print(rig.summary())

Errors name the caller's fields (``settings.fields``: the command line's options
for ``ffexp emulate``). Network faults common to every link are ``faults``
(:class:`~drivers.emulate.faults.FaultSettings`); a family's own are ``family_faults``
(``--fault name=value``, the names its entry lists).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from importlib import import_module
from pathlib import Path
from types import MappingProxyType, TracebackType
from typing import Any, Literal

from drivers import registry
from drivers.description.scene import Scene
from drivers.emulate.camera_stream import CameraStream
from drivers.emulate.faults import FaultSettings
from drivers.emulate.netft_box import NetFtServer
from drivers.emulate.served import ServedRobot
from drivers.errors import ConfigError, NotConnectedError
from drivers.world.world import SimWorld

__all__ = ["EmulatedRig", "EmulatedRigSettings", "SettingNames"]


@dataclass(frozen=True)
class SettingNames:
    """How errors name the settings (the command line's options by default)."""

    port: str = "--port"
    netft_port: str = "--netft-port"
    camera_port: str = "--camera-port"
    camera_calibration: str = "--camera-calibration"
    listen: str = "--listen"
    robot: str = "--robot"
    remote: str = "--remote"
    fault: str = "--fault"


@dataclass(frozen=True)
class EmulatedRigSettings:
    """What the emulated rig serves and how.

    Args:
        scene: the rig to simulate.
        remote: a controller that sends to its client (FRI): the remote driver's address
            (``FRIHOST``, ``FRISOCK`` on a KRC).
        seed: the world's seed (None: the scene's).
        port: local UDP port a sending controller sends from (0: any).
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
        robot: an emulated controller's name (:func:`drivers.registry.emulators`: ``lwr4``,
            a KRC2 LR over FRI; ``ur5e``, a UR controller over RTDE; ...); the scene's arm
            must be its arm.
        listen: a robot whose link the client opens: where its server listens (any
            loopback address may be chosen; None: the robot's default).
        family_faults: the controller's own faults by name (its entry's ``faults``), e.g.
            ``disconnect_after`` of the ``ur5e``.
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
    robot: str = field(default_factory=lambda: registry.emulators()[0].name)
    listen: tuple[str, int] | None = None
    family_faults: Mapping[str, float] = field(default_factory=lambda: MappingProxyType({}))

    @property
    def max_cycles(self) -> int | None:
        """World steps in ``duration_s`` (None: no limit)."""
        return round(self.duration_s / self.scene.fri.cycle) if self.duration_s > 0 else None


class EmulatedRig:
    """The emulated rig of ``settings`` (module docstring). Open it with ``with``."""

    def __init__(self, settings: EmulatedRigSettings) -> None:
        self.settings = settings
        self.world: SimWorld | None = None
        """The world as opened (a controller may run a fresh one per client session)."""
        self.served: ServedRobot | None = None
        """The family's controller, while open."""
        self.netft: NetFtServer | None = None
        self.camera: CameraStream | None = None
        self._summary: str | None = None

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
        try:
            entry = registry.emulator(s.robot)
        except KeyError:
            names = ", ".join(e.name for e in registry.emulators())
            raise ConfigError(s.fields.robot, s.robot, f"choose one of {names}") from None
        if s.scene.arm.model != s.robot:
            raise ConfigError(s.fields.robot, s.robot, f"the scene ({s.scene.name}) has "
                              f"arm.model {s.scene.arm.model!r}, not {s.robot!r}")
        known = {name for name, _what in entry.faults}
        for name in s.family_faults:
            if name not in known:
                have = ", ".join(sorted(known)) or "none"
                raise ConfigError(s.fields.fault, name,
                                  f"the {s.robot} emulator's own faults are: {have}")
        if s.camera_port is not None and not entry.camera:
            raise ConfigError(s.fields.camera_port, str(s.camera_port),
                              f"the {s.robot} emulator serves no camera")
        if entry.needs_remote and s.remote is None:
            raise ConfigError(s.fields.remote, "", "the remote driver's address is required")
        import_module("drivers.base.signatures").load_kernels()  # none compiles serving
        self.world = world = SimWorld(s.scene, seed=s.seed)
        try:
            if entry.ft_box and s.netft_port is not None:
                self.netft = NetFtServer.open(s.host, s.netft_port, on_bias=world.tare_ft,
                                              field=s.fields.netft_port)
            module, name = entry.serve.split(":")
            self.served = getattr(import_module(module), name)(world, s, self.netft)
            if s.camera_port is not None:
                self.camera = CameraStream(world, s.host, s.camera_port, fps=s.camera_fps,
                                           field=s.fields.camera_port)
                if s.camera_calibration is not None:
                    self._write_calibration(self.camera, s.camera_calibration)
        except BaseException:
            self.close()
            raise

    def _write_calibration(self, camera: CameraStream, path: Path) -> None:
        try:
            camera.write_calibration(path)
        except OSError as exc:
            raise ConfigError(self.settings.fields.camera_calibration, str(path),
                              exc.strerror or str(exc)) from None

    def stop(self) -> None:
        """Ask the controller to stop after its current cycle (thread-safe)."""
        if self.served is not None:
            self.served.stop()

    def close(self) -> None:
        """Stop serving and close every server (idempotent)."""
        served, self.served = self.served, None
        if served is not None:
            served.close()  # closes the Net F/T box it was given too
            self._summary = served.summary()
        elif self.netft is not None:
            self.netft.close()
        self.netft = None
        camera, self.camera = self.camera, None
        if camera is not None:
            camera.close()

    # ------------------------------------------------------------ serving
    def ready_line(self) -> str:
        """One line: where the controller serves, to whom, the Net F/T box and camera, cycle,
        pacing."""
        s = self.settings
        served = self._require()
        extra = ""
        if registry.emulator(s.robot).ft_box:
            extra = (f", Net F/T on {s.host}:{self.netft.address[1]}"
                     if self.netft is not None else ", no Net F/T")
        if self.camera is not None:
            extra += (f", camera on http://{s.host}:{self.camera.port}/stream.mjpg at "
                      f"{s.camera_fps:g} fps")
        return (f"{served.ready_line()}{extra}, cycle {s.scene.fri.cycle * 1000.0:g} ms, "
                f"{s.pacing}")

    def serve(self, stop_requested: Callable[[], bool],
              on_status: Callable[[str], None] | None = None) -> Any:
        """Serve until ``duration_s``, ``stop_requested()`` or an error, which is re-raised
        here; ``on_status`` gets a status line now and then. Returns the controller's
        counters (:meth:`ServedRobot.serve`)."""
        served = self._require()

        def on_cycle() -> None:
            if self.camera is not None:  # the camera sees the world between steps, never during
                self.camera.publish()

        return served.serve(stop_requested, on_status, on_cycle, self.settings.max_cycles,
                            self.settings.duration_s)

    def summary(self) -> str:
        """The controller's counters in one line (after close: as they were at close)."""
        if self.served is not None:
            return self.served.summary()
        if self._summary is None:
            raise NotConnectedError("the emulated rig was never opened")
        return self._summary

    def _require(self) -> ServedRobot:
        if self.served is None:
            raise NotConnectedError("the emulated rig is not open (use it as a context manager)")
        return self.served
