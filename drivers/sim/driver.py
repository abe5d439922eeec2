"""The ``sim`` back-ends: in-process lockstep drivers over one :class:`SimWorld`.

``SimRobot.measurements()`` yields the measurement of the current cycle; when
the runner asks for the next one, the world runs one FRI cycle with the last
command :meth:`SimRobot.send` received (the KRC repeats the last command if
none came). ``SimFtSensor.samples()`` returns the F/T samples the world
produced since the last call. Build both with :func:`open_sim`.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from pathlib import Path

from drivers.base.interfaces import ForceTorqueSensor, RobotDriver
from drivers.base.types import Command, FriQuality, FriState, FtSamples, Measurement
from drivers.errors import NotConnectedError
from drivers.sim.scene import Scene, load_scene
from drivers.sim.world import SimWorld


class SimRobot(RobotDriver):
    """LWR4+ over FRI, simulated in lockstep.

    Like a KRL script with ``friOpen``/``friStart`` (and like ``ffexp emulate``
    in lockstep), the link starts in monitor mode (MON, quality BAD, commands
    ignored) and enters command mode (CMD, PERFECT) once the remote has
    answered ``start_cycles`` consecutive cycles; the command of that cycle is
    the first one applied. ``start_cycles = 0`` starts in CMD.

    Args:
        world: the world to step.
        max_cycles: stop yielding after this many cycles (``None``: forever).
        start_cycles: answered cycles before CMD (100, as a friStart script).
    """

    def __init__(
        self, world: SimWorld, max_cycles: int | None = None, start_cycles: int = 100
    ) -> None:
        self.world = world
        self.max_cycles = max_cycles
        self.start_cycles = start_cycles
        self._connected = False
        self._command: Command | None = None
        self._answered = 0

    def connect(self) -> None:
        self._connected = True
        self._answered = 0
        if self.start_cycles > 0 and self.world.fri_state == FriState.CMD:
            self.world.fri_state = FriState.MON
            self.world.fri_quality = FriQuality.BAD
            m = self.world.last_measurement
            m.state, m.quality = FriState.MON, FriQuality.BAD

    def close(self) -> None:
        self._connected = False

    @property
    def connected(self) -> bool:
        return self._connected

    def measurements(self) -> Iterator[Measurement]:
        if not self._connected:
            raise NotConnectedError("sim robot: measurements() before connect()")
        n = 0
        m = self.world.last_measurement
        while self._connected:
            yield m
            n += 1
            if self.max_cycles is not None and n >= self.max_cycles:
                return
            if not self._connected:
                return
            self._answered = self._answered + 1 if self._command is not None else 0
            world = self.world
            if world.fri_state == FriState.MON and self._answered >= self.start_cycles:
                world.fri_state = FriState.CMD
                world.fri_quality = FriQuality.PERFECT
            m = world.step(self._command)
            self._command = None

    def send(self, command: Command) -> None:
        if not self._connected:
            raise NotConnectedError("sim robot: send() before connect()")
        self._command = command


class SimFtSensor(ForceTorqueSensor):
    """The Mini45 model of a :class:`SimWorld`, read like a Net F/T stream."""

    def __init__(self, world: SimWorld) -> None:
        self.world = world
        self._running = False

    def start(self) -> None:
        self.world.ft_samples()  # a fresh stream starts now
        self._running = True

    def stop(self) -> None:
        self._running = False

    @property
    def running(self) -> bool:
        return self._running

    def samples(self) -> FtSamples:
        if not self._running:
            raise NotConnectedError("sim F/T sensor: samples() before start()")
        return self.world.ft_samples()

    def tare(self) -> None:
        if not self._running:
            raise NotConnectedError("sim F/T sensor: tare() before start()")
        self.world.tare_ft()


def open_sim(
    scene: Scene | Path | str,
    seed: int | None = None,
    overrides: Iterable[str] = (),
    max_cycles: int | None = None,
    start_cycles: int = 100,
) -> tuple[SimRobot, SimFtSensor]:
    """Build a world from a scene (object or TOML path) and its robot/sensor pair."""
    if not isinstance(scene, Scene):
        scene = load_scene(Path(scene), overrides)
    world = SimWorld(scene, seed=seed)
    robot = SimRobot(world, max_cycles=max_cycles, start_cycles=start_cycles)
    return robot, SimFtSensor(world)
