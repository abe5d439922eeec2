"""The FRI emulator (drivers.fri.emulate.server) against the remote driver, lockstep on loopback."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from drivers.base import ApplyStatus, CartesianCommand
from drivers.description.scene import Scene
from drivers.fri.backend import FriRobotConfig
from drivers.fri.driver import FriRobot
from drivers.fri.emulate.lockstep import SimRobot
from drivers.fri.emulate.server import EmulatorSettings, FriEmulator
from drivers.fri.types import FriMeasurement, FriState
from drivers.world.world import SimWorld

LOCAL = "127.0.0.1"
PAPER_K = np.array([5000.0, 0.0, 0.0, 0.0, 300.0, 300.0])
PAPER_D = np.array([0.7, 0.0, 0.0, 0.0, 0.7, 0.7])


def _push(pose: np.ndarray) -> CartesianCommand:
    return CartesianCommand(pose_m=pose.copy(), stiffness_npm_nmprad=PAPER_K.copy(),
                            damping_ratio=PAPER_D.copy(),
                            wrench_n_nm=np.array([0.0, 0.0, 2.0, 0.0, 0.0, 0.0]))


def test_lockstep_over_udp_matches_the_in_process_robot(paper_scene: Scene) -> None:
    """Same link states per cycle, and the same motion up to float32 rounding."""
    n = 160
    robot = FriRobot(FriRobotConfig(robot_ip=LOCAL, port=0, bind_host=LOCAL,
                                    connect_timeout_s=10.0, cycle_timeout_s=10.0))
    emu: FriEmulator | None = None
    states: list[FriState] = []
    z_udp: list[float] = []
    try:
        _, port = robot.bind()
        emu = FriEmulator(SimWorld(paper_scene, seed=2),
                          EmulatorSettings(remote=(LOCAL, port), bind_host=LOCAL,
                                           pacing="lockstep", lockstep_timeout_s=0.5))
        robot.connect()
        emu.start_thread(max_cycles=n)
        cmd: CartesianCommand | None = None
        for s in robot.measurements():
            assert isinstance(s.extras, FriMeasurement)
            states.append(s.extras.state)
            z_udp.append(float(s.tcp_pose_m[0, 3]))
            cmd = cmd or _push(s.tcp_pose_m)
            robot.send(cmd)
            if len(states) == n:
                break
        emu.join(timeout=30.0)
        assert emu.stats.missed == 0 and emu.stats.starts == 1
    finally:
        if emu is not None:
            emu.close()
        robot.close()
    sim = SimRobot(SimWorld(paper_scene, seed=2), max_cycles=n)
    ref_states: list[FriState] = []
    z_ref: list[float] = []
    with sim:
        cmd = None
        for s in sim.measurements():
            assert isinstance(s.extras, FriMeasurement)
            ref_states.append(s.extras.state)
            z_ref.append(float(s.tcp_pose_m[0, 3]))
            cmd = cmd or _push(s.tcp_pose_m)
            status = sim.send(cmd).status
            assert status == (ApplyStatus.APPLIED if s.link.commanding else ApplyStatus.MIRRORED)
    assert states == ref_states
    assert states.index(FriState.CMD) == 100
    np.testing.assert_allclose(z_udp, z_ref, atol=1e-6)
    assert z_ref[-1] - z_ref[100] > 1e-4  # the push moved the tool once commanding


@pytest.mark.slow
def test_a_whole_run_over_udp_equals_the_in_process_run_at_wire_precision(tmp_path: Path) -> None:
    """Lockstep over UDP and the in-process KRC with ``wire_precision`` (measurement and
    command through the FRI codec) give the same run, bit for bit: same outcome, same
    poses, estimates and commands every cycle (F/T: the KRC's own estimate, which
    travels in the FRI packet; the alignment judged from the settings, as without truth)."""
    from link_harness import PROTOCOL, ROOT, emulated_run

    from drivers.description.scene import load_scene
    from drivers.fri.estimate import FriEstimateSensor
    from ffexp import loop
    from ffexp.protocol import load_run_protocol
    from ffexp.recording import Recorder, load
    from ffexp.runlog import RunLog

    overrides = ["run.timeout_s=12", "alignment.source=settings"]
    udp = emulated_run(tmp_path, overrides, lockstep_timeout_s=0.5)
    protocol = load_run_protocol(PROTOCOL, overrides)
    world = SimWorld(load_scene(ROOT / "data" / "scenes" / "paper.toml"), seed=protocol.seed)
    robot = SimRobot(world, wire_precision=True)
    path = tmp_path / "in_process.mcap"
    with Recorder(path) as rec:
        local = loop.run(protocol, robot, FriEstimateSensor(robot),
                         RunLog(rec, 1_700_000_000 * 10**9, protocol.run.tf_period_s))
    here = load(path)
    assert local.contacts >= 1 and local.aligned == udp.outcome.aligned  # it reached ALIGN
    assert (local.phase, local.stop_reason, local.cycles, local.duration_s, local.breaks) == (
        udp.outcome.phase, udp.outcome.stop_reason, udp.outcome.cycles,
        udp.outcome.duration_s, udp.outcome.breaks)
    for topic, field in (("/robot/state", "tcp_pose"), ("/estimator/state", "wrench"),
                         ("/control/command", "wrench"), ("/control/terms", "total")):
        np.testing.assert_array_equal(here.topic(topic)[field], udp.rec.topic(topic)[field])
