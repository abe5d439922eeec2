"""The KRC's software limit switches: a joint at its limit ends CMD, latches an error, holds.

In-process lockstep robot (drivers.fri.emulate.lockstep), the UDP emulator
(drivers.fri.emulate.server) against the remote driver, and the runner.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from drivers.base import CartesianCommand
from drivers.description.scene import Scene, load_scene
from drivers.errors import DriverError
from drivers.fri.backend import FriRobotConfig
from drivers.fri.driver import FriRobot
from drivers.fri.emulate.krc import (
    HARDWARE_LIMITS_DEG,
    SOFTWARE_LIMITS_DEG,
    software_limit_error,
)
from drivers.fri.emulate.lockstep import SimRobot, open_sim
from drivers.fri.emulate.server import EmulatorSettings, FriEmulator
from drivers.fri.link import ERROR_SOFTWARE_LIMIT, KrcLink, LinkEvent, describe_error
from drivers.fri.types import FriMeasurement, FriState
from drivers.world.arm import ArmMode
from drivers.world.world import SimWorld
from ffexp import loop
from ffexp.contracts import StopReason
from ffexp.protocol import load_run_protocol, scene_path
from ffexp.runlog import RunLog

ROOT = Path(__file__).resolve().parent.parent
HARD_RAD = np.radians(HARDWARE_LIMITS_DEG)
SOFT_RAD = np.radians(SOFTWARE_LIMITS_DEG)
LOCAL = "127.0.0.1"


def _free_push(pose: np.ndarray, cmd: CartesianCommand) -> CartesianCommand:
    """A constant 5 N push along the tool's Z with no translational stiffness."""
    cmd.pose_m[:] = pose
    cmd.stiffness_npm_nmprad[:] = (0.0, 0.0, 0.0, 200.0, 200.0, 200.0)
    cmd.damping_ratio[:] = 0.7
    cmd.wrench_n_nm[:] = (0.0, 0.0, 5.0, 0.0, 0.0, 0.0)
    return cmd


@pytest.fixture(scope="module")
def far_scene(paper_scene_path: Path) -> Scene:
    return load_scene(paper_scene_path, ["target.distance=0.6"])


def test_error_bits_name_the_joints_at_their_limits() -> None:
    q = np.zeros(7)
    assert software_limit_error(q, SOFT_RAD) == 0
    q[1] = -SOFT_RAD[1]  # at the limit counts
    q[6] = SOFT_RAD[6] + 0.1
    q[3] = SOFT_RAD[3] - 1e-9
    error = software_limit_error(q, SOFT_RAD)
    assert error == (1 << 1) | (1 << 6)
    assert error & ~ERROR_SOFTWARE_LIMIT == 0
    assert describe_error(error) == "A2, A7 at the software limit switch"
    assert describe_error(0) == ""


def test_a_fault_ends_cmd_and_blocks_the_start_until_acknowledged() -> None:
    link = KrcLink(0.005, start_cycles=0)
    assert link.commanding
    assert link.fault(0x2) is LinkEvent.FALLBACK
    assert link.state == FriState.MON and link.error == 0x2
    events = {link.cycle(True) for _ in range(300)}  # a perfect link, answered every cycle
    assert events == {LinkEvent.NONE} and not link.commanding
    assert link.fault(0x4) is LinkEvent.NONE and link.error == 0x6  # latched, accumulated
    link.acknowledge()
    assert link.cycle(True) is LinkEvent.START and link.commanding


def test_lockstep_push_stops_at_the_software_limit_and_holds(far_scene: Scene) -> None:
    """Today's failure: a 5 N push for 15 s drove joints past the LWR4+ ranges."""
    robot = SimRobot(SimWorld(far_scene), start_cycles=0, max_cycles=3000)
    qs: list[np.ndarray] = []
    last: FriMeasurement | None = None
    cmd = CartesianCommand()
    robot.connect()
    with pytest.raises(DriverError) as info:
        for s in robot.measurements():
            assert isinstance(s.extras, FriMeasurement)
            last = s.extras
            qs.append(s.joint_pos_rad.copy())
            if last.error:
                assert last.state == FriState.MON and not s.link.commanding
            else:
                assert last.state == FriState.CMD
            robot.send(_free_push(s.tcp_pose_m, cmd))
    message = str(info.value)
    assert "KRC stopped the robot" in message and "software limit switch" in message
    assert last is not None and last.error != 0
    joint = int(np.flatnonzero([last.error & (1 << i) for i in range(7)])[0])
    assert f"A{joint + 1} " in message
    q = np.array(qs)
    assert len(q) < 3000  # it stopped long before 15 s
    assert np.all(np.abs(q) < HARD_RAD)  # never beyond the hardware range
    # beyond the software limit by at most one cycle of motion
    speed = np.max(np.abs(np.diff(q, axis=0)), axis=0)
    assert np.all(np.abs(q) <= SOFT_RAD + speed + 1e-9)
    assert abs(q[-1, joint]) >= SOFT_RAD[joint] > abs(q[-2, joint])
    # the brakes: joint position hold where it stopped, no more motion
    world = robot.world
    assert world.mode == ArmMode.JOINT_POSITION
    q_brake = world.last_state.cmd_jnt_pos_rad.copy()  # where the brakes hold
    np.testing.assert_allclose(q_brake, q[-1], atol=0.02)  # one cycle's motion at most
    for _ in range(100):
        world.advance(None)
    q_settled = world.data.qpos[:7].copy()
    for _ in range(100):
        world.advance(None)
        assert np.all(np.abs(world.data.qpos[:7]) < HARD_RAD)
    assert np.max(np.abs(world.data.qpos[:7] - q_settled)) < 1e-4
    assert np.max(np.abs(world.data.qpos[:7] - q_brake)) < 5e-3


def test_the_runner_aborts_with_the_reason() -> None:
    """A paper run whose approach drives A2 (from -20.2 deg) into a 23 deg switch."""
    ppath = ROOT / "protocols" / "method1_case1.toml"
    proto = load_run_protocol(ppath, ["run.timeout_s=5", "run.stop_hold_s=0"])
    limits = list(SOFTWARE_LIMITS_DEG)
    limits[1] = 23.0
    robot, sensor = open_sim(scene_path(ppath, proto), seed=proto.seed,
                             overrides=proto.scene.set, software_limits_deg=limits)
    out = loop.run(proto, robot, sensor, RunLog(None, 0, 0.1))
    assert out.stop_reason is StopReason.DRIVER_ERROR
    assert "A2 reached its software limit switch" in out.reason
    assert out.duration_s < 5.0
    assert abs(float(robot.world.data.qpos[1])) < np.radians(23.5)


def test_software_limits_are_validated(far_scene: Scene) -> None:
    with pytest.raises(ValueError, match="software_limits_deg"):
        SimRobot(SimWorld(far_scene), software_limits_deg=(160.0, 110.0))
    with pytest.raises(ValueError, match="software_limits_deg"):
        SimRobot(SimWorld(far_scene), software_limits_deg=(160.0, 125.0, 160.0, 110.0,
                                                           160.0, 110.0, 160.0))


def test_udp_emulator_stops_and_reports_the_error(far_scene: Scene) -> None:
    """Over FRI: the KRC leaves CMD with the error bits; the driver then names the joint."""
    robot = FriRobot(FriRobotConfig(robot_ip=LOCAL, port=0, bind_host=LOCAL,
                                    connect_timeout_s=10.0, cycle_timeout_s=10.0))
    emu: FriEmulator | None = None
    msrs: list[tuple[FriState, int]] = []
    limits = list(SOFTWARE_LIMITS_DEG)
    limits[3] = 95.0  # A4 starts at 98.2 deg and opens under the push: trips in CMD
    try:
        _, port = robot.bind()
        emu = FriEmulator(SimWorld(far_scene),
                          EmulatorSettings(remote=(LOCAL, port), bind_host=LOCAL,
                                           pacing="lockstep", lockstep_timeout_s=0.5,
                                           start_cycles=0, software_limits_deg=tuple(limits)))
        robot.connect()
        emu.start_thread(max_cycles=400)
        cmd = CartesianCommand()
        with pytest.raises(DriverError, match="A4 at the software limit switch"):
            for s in robot.measurements():
                assert isinstance(s.extras, FriMeasurement)
                msrs.append((s.extras.state, s.extras.error))
                robot.send(_free_push(s.tcp_pose_m, cmd))
                if len(msrs) == 400:
                    break
        assert emu.stats.limit_stops == 1 and emu.stats.fallbacks == 1
    finally:
        if emu is not None:
            emu.close()
        robot.close()
    # it was commanding, without error, up to the cycle the switch tripped
    assert len(msrs) >= 1
    assert all(st == FriState.CMD and e == 0 for st, e in msrs)
