"""The KRC's command timing (``fri.command_delay_cycles``): the answer to measurement k
acts from cycle k + d, in-process and over UDP in lockstep (one implementation:
:class:`drivers.fri.emulate.krc.CommandDelay`)."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from drivers.base import CartesianCommand, RobotDriver, RobotState
from drivers.description.scene import Scene
from drivers.fri.backend import FriRobotConfig
from drivers.fri.driver import FriRobot
from drivers.fri.emulate.krc import CommandDelay
from drivers.fri.emulate.lockstep import SimRobot
from drivers.fri.emulate.server import EmulatorSettings, FriEmulator
from drivers.world.arm import ArmCommand
from drivers.world.world import SimWorld

LOCAL = "127.0.0.1"
N = 12
STEP_M = 0.001


def _probe(robot: RobotDriver, states: Iterator[RobotState], world: SimWorld) -> list[float]:
    """Answer cycle k with a set-point k mm below the start pose; return, per cycle j, the
    set-point the world held during cycle j (read after it ran), in mm below the start."""
    first = next(states)
    start = first.tcp_pose_m.copy()
    held: list[float] = []
    cmd = CartesianCommand(pose_m=start.copy(), stiffness_npm_nmprad=np.full(6, 500.0),
                           damping_ratio=np.full(6, 0.7), wrench_n_nm=np.zeros(6))
    for k in range(N):
        cmd.pose_m[2, 3] = start[2, 3] - STEP_M * k
        robot.send(cmd)
        next(states)  # cycle k has run
        held.append(round((start[2, 3] - world.last_state.cmd_cart_pose_m[2, 3]) / STEP_M, 6))
    return held


def _expected(d: int) -> list[float]:
    return [0.0] * d + [float(k) for k in range(N - d)]


def _scene(paper_scene: Scene, d: int) -> Scene:
    fri = paper_scene.fri.model_copy(update={"command_delay_cycles": d})
    return paper_scene.model_copy(update={"fri": fri})


@pytest.mark.parametrize("d", [0, 1, 3])
def test_in_process_the_answer_to_k_acts_from_cycle_k_plus_d(paper_scene: Scene, d: int) -> None:
    world = SimWorld(_scene(paper_scene, d), seed=1)
    robot = SimRobot(world, start_cycles=0)
    with robot:
        assert _probe(robot, robot.measurements(), world) == _expected(d)


@pytest.mark.parametrize("d", [0, 2])
def test_over_udp_in_lockstep_the_answer_to_k_acts_from_cycle_k_plus_d(
        paper_scene: Scene, d: int) -> None:
    world = SimWorld(_scene(paper_scene, d), seed=1)
    robot = FriRobot(FriRobotConfig(robot_ip=LOCAL, port=0, bind_host=LOCAL,
                                    connect_timeout_s=10.0, cycle_timeout_s=10.0))
    emu: FriEmulator | None = None
    try:
        _, port = robot.bind()
        emu = FriEmulator(world, EmulatorSettings(remote=(LOCAL, port), bind_host=LOCAL,
                                                  pacing="lockstep", lockstep_timeout_s=0.5,
                                                  start_cycles=0))
        robot.connect()
        emu.start_thread(max_cycles=N + 2)
        held = _probe(robot, iter(robot.measurements()), world)
        emu.join(timeout=30.0)
    finally:
        if emu is not None:
            emu.close()
        robot.close()
    # float32 on the wire: the set-points to a micrometre
    np.testing.assert_allclose(held, _expected(d), atol=1e-3)


def test_a_stop_discards_what_was_in_flight() -> None:
    delay = CommandDelay(2)
    a, b = ArmCommand(tcp_wrench_n_nm=np.ones(6)), ArmCommand(tcp_wrench_n_nm=np.full(6, 2.0))
    assert delay.push(a, 7) == (None, None)
    assert delay.push(b, 8) == (None, None)
    out, seq = delay.push(None)
    assert seq == 7 and out is not None and out.tcp_wrench_n_nm is not None
    a.tcp_wrench_n_nm[:] = 5.0  # the caller reuses its arrays: the delayed copy is its own
    assert np.all(out.tcp_wrench_n_nm == 1.0)
    delay.clear()
    assert delay.push(None) == (None, None) and delay.push(None) == (None, None)
    assert CommandDelay(0).push(a, 3) == (a, 3)
