"""A paper protocol over UDP (in-process threads) against the same run in-process.

Over FRI the run differs from the plain in-process one in three documented
ways: the emulated KRC starts in MON and enters CMD after 100 answered
cycles (``friStart``), the wire is float32, and ground truth does not travel
(alignment is judged from settings). An in-process robot with exactly those
three properties must give the same outcome as the run over UDP; this is
what makes ``--driver fri`` against the lockstep emulator a faithful stand-in.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from drivers.base.interfaces import RobotDriver
from drivers.base.types import Command, FriState, Measurement
from drivers.fri.emulator import EmulatorSettings, FriEmulator
from drivers.netft.emulator import NetFtServer
from drivers.sim.driver import SimFtSensor
from drivers.sim.scene import load_scene
from drivers.sim.world import SimWorld
from ffexp.experiment import LinkOptions, open_drivers
from ffexp.protocol import load_run_protocol, scene_path
from ffexp.recording import Recorder
from ffexp.runner import Runner, RunOutcome

ROOT = Path(__file__).resolve().parent.parent


def f32(a: np.ndarray) -> np.ndarray:
    return np.asarray(a, dtype=np.float64).astype(np.float32).astype(np.float64)


class LikeTheWire(RobotDriver):
    """In-process: MON for the first 100 cycles, float32 both ways, no truth."""

    def __init__(self, world: SimWorld, start_after: int = 100) -> None:
        self.world = world
        self.start_after = start_after
        self._connected = False
        self._cmd: Command | None = None

    def connect(self) -> None:
        self._connected = True

    def close(self) -> None:
        self._connected = False

    @property
    def connected(self) -> bool:
        return self._connected

    def _wire(self, m: Measurement, state: FriState) -> Measurement:
        out = dataclasses.replace(m, state=state, truth=None)
        for f in dataclasses.fields(Measurement):
            v = getattr(out, f.name)
            if isinstance(v, np.ndarray) and v.dtype == np.float64:
                setattr(out, f.name, f32(v))
        return out

    def measurements(self) -> Iterator[Measurement]:
        w = self.world
        w.fri_state = FriState.MON
        n = 0
        m = self._wire(w.last_measurement, FriState.MON)
        while self._connected:
            yield m
            n += 1
            if n >= self.start_after:
                w.fri_state = FriState.CMD
            cmd = self._cmd
            if cmd is not None:
                cmd = dataclasses.replace(
                    cmd, **{f.name: f32(getattr(cmd, f.name)) for f in dataclasses.fields(Command)
                            if isinstance(getattr(cmd, f.name), np.ndarray)
                            and getattr(cmd, f.name).dtype == np.float64})
            self._cmd = None
            m = self._wire(w.step(cmd), w.fri_state)

    def send(self, command: Command) -> None:
        self._cmd = command


def run_udp(protocol_path: Path, tmp: Path) -> RunOutcome:
    p = load_run_protocol(protocol_path)
    world = SimWorld(load_scene(scene_path(protocol_path, p), p.scene.set), seed=p.seed)
    server = NetFtServer.open("127.0.0.1", 0, on_bias=world.tare_ft)
    emu: FriEmulator | None = None
    try:
        link = LinkOptions(robot_ip="127.0.0.1", fri_port=0, netft=f"127.0.0.1:{server.address[1]}")
        robot, sensor, meta, _ = open_drivers("fri", protocol_path, p, link)
        emu = FriEmulator(world, EmulatorSettings(
            remote=("127.0.0.1", int(meta["fri_port"])), bind_host="127.0.0.1",
            pacing="lockstep"), server)
        emu.start_thread()
        with Recorder(tmp / "udp.mcap") as rec:
            return Runner(p, robot, sensor, rec, start_utc_ns=0).run()
    finally:
        if emu is not None:
            emu.close()
        else:
            server.close()


def run_like_the_wire(protocol_path: Path, tmp: Path) -> RunOutcome:
    p = load_run_protocol(protocol_path)
    world = SimWorld(load_scene(scene_path(protocol_path, p), p.scene.set), seed=p.seed)
    with Recorder(tmp / "local.mcap") as rec:
        return Runner(p, LikeTheWire(world), SimFtSensor(world), rec, start_utc_ns=0).run()


@pytest.mark.slow
def test_method2_over_udp_has_the_outcome_of_the_same_run_in_process(tmp_path: Path) -> None:
    path = ROOT / "protocols" / "method2.toml"
    udp = run_udp(path, tmp_path)
    local = run_like_the_wire(path, tmp_path)
    assert (udp.phase, udp.aligned, udp.contacts, udp.breaks) == (
        local.phase, local.aligned, local.contacts, local.breaks)
    assert udp.reason.split(":")[0] == local.reason.split(":")[0]
    assert abs(udp.duration_s - local.duration_s) <= 0.02
