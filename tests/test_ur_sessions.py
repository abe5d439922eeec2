"""The emulated UR5e's sessions: each client that starts streaming after the last session ended
finds the emulator as it was started (world, program, registers), so a campaign over RTDE runs
every protocol from the same start as in-process; ``reset_per_session=False`` goes on."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_ur_sim import _drive

from drivers.description import load_scene
from drivers.ur import registers
from drivers.ur.config import UrSettings
from drivers.ur.driver import UrRobot
from drivers.ur.emulate.server import UrEmulator
from drivers.ur.registers import Mode
from drivers.ur.rtde.client import RtdeClient
from drivers.world.world import SimWorld

ROOT = Path(__file__).resolve().parents[1]
CYCLES = 40


@pytest.fixture(scope="module")
def scene():  # type: ignore[no-untyped-def]
    return load_scene(ROOT / "data/scenes/paper-ur5e.toml")


def _session(port: int, push_n: float) -> list[tuple[np.ndarray, ...]]:
    """One client's run against the emulator: force mode along Z with ``push_n``."""
    return _drive(UrRobot(UrSettings(robot_ip="127.0.0.1", rtde_port=port, script="installed",
                                     cycle_timeout_s=5.0)), CYCLES, push_n)


def _equal(a: list[tuple[np.ndarray, ...]], b: list[tuple[np.ndarray, ...]]) -> bool:
    return len(a) == len(b) and all(
        np.array_equal(x, y) for ra, rb in zip(a, b, strict=True) for x, y in zip(ra, rb,
                                                                                 strict=True))


def test_each_session_starts_from_the_emulators_start(scene) -> None:  # type: ignore[no-untyped-def]
    emu = UrEmulator(SimWorld(scene, seed=3), "127.0.0.1", 0, pacing="lockstep").start()
    try:
        first = _session(emu.address[1], 2.0)
        other = _session(emu.address[1], 6.0)  # a different run in between
        again = _session(emu.address[1], 2.0)
    finally:
        emu.close()
    moved = first[-1][1][:3, 3] - first[0][1][:3, 3]
    assert abs(moved[0]) > 1e-4  # the push moved the tool along TCF Z (world x)
    assert _equal(first, again)  # bit for bit: the world, the program and the registers anew
    assert not _equal(first, other)
    assert other[0][0] == first[0][0]  # its clock starts where the first one's did
    assert emu.sessions == 3 and emu.steps >= 3 * CYCLES
    assert emu.server.counters["sessions"] == 3


def test_without_resets_a_session_goes_on_where_the_last_one_left(scene) -> None:  # type: ignore[no-untyped-def]
    emu = UrEmulator(SimWorld(scene, seed=3), "127.0.0.1", 0, pacing="lockstep",
                     reset_per_session=False).start()
    try:
        first = _session(emu.address[1], 2.0)
        second = _session(emu.address[1], 2.0)
    finally:
        emu.close()
    assert second[0][0] > first[-1][0]  # the world's clock went on
    assert not np.array_equal(second[0][1], first[0][1])


def test_registers_written_before_the_start_survive_the_new_session(scene) -> None:  # type: ignore[no-untyped-def]
    emu = UrEmulator(SimWorld(scene, seed=3), "127.0.0.1", 0, pacing="lockstep").start()
    try:
        _session(emu.address[1], 2.0)
        with RtdeClient("127.0.0.1", emu.address[1], timeout_s=5.0) as client:
            client.setup_outputs(["timestamp", registers.APPLIED_SEQ], 500.0)
            inputs = client.setup_inputs([registers.SEQ, registers.MODE])
            client.send(inputs, {registers.SEQ: 41, registers.MODE: int(Mode.HOLD)})
            client.start()
            package = client.receive(5.0)
    finally:
        emu.close()
    assert emu.sessions == 2
    assert emu.server.inputs[registers.SEQ] == 41  # kept for the new program
    assert package.record["timestamp"] == pytest.approx(scene.fri.cycle)  # the world anew
    assert package.record[registers.APPLIED_SEQ] == 41  # the new program applied it


def test_a_pause_and_a_start_again_is_the_same_session(scene) -> None:  # type: ignore[no-untyped-def]
    emu = UrEmulator(SimWorld(scene, seed=3), "127.0.0.1", 0, pacing="lockstep").start()
    try:
        with RtdeClient("127.0.0.1", emu.address[1], timeout_s=5.0) as client:
            client.setup_outputs(["timestamp"], 500.0)
            client.start()
            before = [float(client.receive(5.0).record["timestamp"]) for _ in range(5)]
            client.pause()
            client.start()
            after = float(client.receive(5.0).record["timestamp"])
    finally:
        emu.close()
    assert before[0] == pytest.approx(scene.fri.cycle)
    assert after > before[-1]  # the world went on
    assert emu.sessions == 1 and emu.server.counters["sessions"] == 1
