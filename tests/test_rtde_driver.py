"""``UrRobot`` against our RTDE server playing a UR controller running ffexp's URScript program.

The stand-in controller (:class:`FakeUr`) does what ``drivers/ur/ffexp_control.script``
does with the registers, at the level the driver can see: it echoes the
command's sequence number, moves the TCP to the commanded pose, and reports
the robot and safety state it is told to. The server runs in lockstep and
waits for the driver's answer, so the package after command k shows command k.
"""

from __future__ import annotations

import math
import socket
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from drivers.base.types import ApplyStatus, CartesianCommand
from drivers.config import load_model
from drivers.description.ur5e import DH_D_M, UR5E
from drivers.errors import (
    AddressError,
    ConfigError,
    DriverTimeoutError,
    LinkLostError,
    PacketEncodeError,
)
from drivers.ur import registers
from drivers.ur.config import UrSettings
from drivers.ur.driver import OUTPUT_NAMES, UrRobot, control_script
from drivers.ur.emulate.rtde_server import RtdeServer
from drivers.ur.errors import UrSafetyStopError
from drivers.ur.registers import Mode
from drivers.ur.rtde.fields import Recipe
from drivers.ur.rtde.variables import INPUTS
from drivers.ur.wrench import UrWrenchSensor

HOST = "127.0.0.1"
DOWN = np.array([0.4, 0.1, 0.3, math.pi, 0.0, 0.0])  # tool z pointing down: R = diag(1, -1, -1)


class FakeUr:
    def __init__(self) -> None:
        self.inputs: dict[str, Any] = {}
        self.k = 0
        self.safety_bits = 1
        self.safety_mode = 1
        self.stop_from_seq = 1 << 40  # the answer after which the robot reports a stop
        self.stop_bits, self.stop_mode = 1 << 2, 3  # protective stop
        self.modes: list[int] = []
        self.ended = threading.Event()

    def sink(self, values: Any) -> None:
        self.inputs.update(values)
        self.modes.append(int(values[registers.MODE]))
        if self.modes[-1] == Mode.END:
            self.ended.set()

    def source(self) -> dict[str, object]:
        k, self.k = self.k, self.k + 1
        moving = self.inputs.get(registers.MODE, 0) in (Mode.SERVO, Mode.FORCE)
        pose = [self.inputs[n] for n in registers.POSE] if moving else DOWN
        stopped = self.inputs.get(registers.SEQ, 0) >= self.stop_from_seq
        return {"timestamp": k * 0.002, "actual_q": np.full(6, k * 1e-3),
                "actual_qd": np.zeros(6), "actual_TCP_pose": pose,
                "actual_TCP_speed": np.array([0.1, 0.0, 0.0, 0.0, 0.0, 0.2]),
                "actual_TCP_force": np.array([0.0, 1.0, -5.0, 0.0, 0.0, 0.0]),
                "ft_raw_wrench": np.arange(6.0), "robot_mode": 7,
                "safety_mode": self.stop_mode if stopped else self.safety_mode,
                "safety_status_bits": self.stop_bits if stopped else self.safety_bits,
                "runtime_state": 2,
                registers.APPLIED_SEQ: self.inputs.get(registers.SEQ, 0),
                registers.SCRIPT_STATE: 1}


@pytest.fixture
def fake() -> Iterator[tuple[FakeUr, RtdeServer]]:
    ur = FakeUr()
    with RtdeServer(ur.source, ur.sink, host=HOST, port=0, pacing="lockstep",
                    outputs=OUTPUT_NAMES) as srv:
        yield ur, srv


def robot_for(srv: RtdeServer) -> UrRobot:
    return UrRobot(UrSettings(robot_ip=HOST, rtde_port=srv.port, script="installed",
                              connect_timeout_s=5.0, cycle_timeout_s=5.0))


def command(z_stiffness: float = 0.0) -> CartesianCommand:
    cmd = CartesianCommand()
    cmd.pose_m[:3, :3] = np.diag([1.0, -1.0, -1.0])
    cmd.pose_m[:3, 3] = [0.45, 0.12, 0.25]
    cmd.stiffness_npm_nmprad[:] = [2000, 2000, z_stiffness, 200, 200, 200]
    cmd.wrench_n_nm[:] = [1.0, 2.0, -3.0, 0.1, 0.2, 0.3]
    return cmd


def test_a_force_command_reaches_the_registers_and_the_state_comes_back(fake: Any) -> None:
    ur, srv = fake
    with robot_for(srv) as robot:
        assert str(robot.controller_version) == "5.15.0.0"
        states = robot.measurements()
        first = next(states)
        np.testing.assert_allclose(first.tcp_pose_m[:3, :3], np.diag([1.0, -1.0, -1.0]),
                                   atol=1e-12)
        # the base-frame wrench and twist, in the TCF (R = diag(1, -1, -1))
        np.testing.assert_allclose(first.ext_wrench_n_nm, [0, -1, 5, 0, 0, 0], atol=1e-12)
        np.testing.assert_allclose(first.tcp_twist_mps_radps, [0.1, 0, 0, 0, 0, -0.2],
                                   atol=1e-12)
        assert first.link.commanding and first.link.healthy and first.link.cycle_s == 0.002
        applied = robot.send(command())
        assert applied.status == ApplyStatus.APPLIED
        np.testing.assert_array_equal(applied.command.wrench_n_nm, [0, 0, -3.0, 0, 0, 0])
        second = next(states)
        assert ur.inputs[registers.MODE] == Mode.FORCE and ur.inputs[registers.SELECTION] == 4
        assert [ur.inputs[n] for n in registers.WRENCH] == [0, 0, -3.0, 0, 0, 0]
        assert [ur.inputs[n] for n in registers.LIMITS] == [0.05, 0.05, 0.1, 0.17, 0.17, 0.17]
        assert ur.inputs[registers.DAMPING] == 0.005 and ur.inputs[registers.SERVO_GAIN] == 300
        np.testing.assert_allclose(second.tcp_pose_m, command().pose_m, atol=1e-12)
        assert second.extras is not None and second.extras.applied_seq == 1  # type: ignore
        robot.send(command(z_stiffness=500.0))  # no compliant axis: a pure pose servo
        next(states)
        assert ur.inputs[registers.MODE] == Mode.SERVO and ur.inputs[registers.SELECTION] == 0
        held = robot.send(None)
        assert held.status == ApplyStatus.HELD
        next(states)
        assert ur.inputs[registers.MODE] == Mode.HOLD
        assert ur.inputs[registers.SEQ] == 3
    assert ur.ended.wait(10.0) and ur.modes[-1] == Mode.END  # close() ends the program
    assert not robot.connected


def test_a_protective_stop_ends_the_run_naming_the_address(fake: Any) -> None:
    ur, srv = fake
    ur.stop_from_seq = 3
    with robot_for(srv) as robot:
        states = robot.measurements()
        for _ in range(3):
            next(states)
            robot.send(None)
        with pytest.raises(UrSafetyStopError) as err:
            next(states)
    assert str(err.value) == (f"{HOST}:{srv.port}: robot stopped for safety: "
                              "protective_stopped (safety_mode PROTECTIVE_STOP)")


def test_an_emergency_stop_names_every_bit_set(fake: Any) -> None:
    ur, srv = fake
    ur.safety_bits, ur.safety_mode = (1 << 6) | (1 << 7), 7
    with robot_for(srv) as robot, pytest.raises(
            UrSafetyStopError, match="robot_emergency_stopped, emergency_stopped "
            r"\(safety_mode ROBOT_EMERGENCY_STOP\)"):
        next(robot.measurements())


def test_a_lost_connection_is_a_lost_link(fake: Any) -> None:
    _ur, srv = fake
    robot = robot_for(srv)
    robot.connect()
    states = robot.measurements()
    next(states)
    srv.close()
    lost = rf"^{HOST}:{srv.port}: RTDE (controller closed|connection lost)"
    with pytest.raises(LinkLostError, match=lost):
        for _ in range(100):  # the packages already sent, then the close
            robot.send(None)
            next(states)
    robot.close()


def test_the_script_goes_to_the_script_port_whole(fake: Any) -> None:
    _ur, srv = fake
    listener = socket.socket()
    listener.bind((HOST, 0))
    listener.listen(1)
    got: list[bytes] = []

    def take() -> None:
        conn, _ = listener.accept()
        with conn:
            conn.settimeout(10.0)
            while chunk := conn.recv(65536):
                got.append(chunk)

    thread = threading.Thread(target=take, daemon=True)
    thread.start()
    settings = UrSettings(robot_ip=HOST, rtde_port=srv.port, script_port=listener.getsockname()[1],
                          connect_timeout_s=5.0)
    with UrRobot(settings):
        thread.join(10.0)
    listener.close()
    text = b"".join(got).decode()
    assert text == control_script()
    assert "def ffexp_control():" in text and text.rstrip().endswith("ffexp_control()")
    assert f"global B = {registers.BASE}" in text  # the registers the driver writes


def test_settings_are_checked_and_name_the_field(tmp_path: Path) -> None:
    rig = tmp_path / "ur.toml"
    rig.write_text('robot_ip = "10.0.0.5"\nforce_mode_damping = 2.0\n')
    with pytest.raises(ConfigError, match=r"ur\.toml: force_mode_damping: "):
        load_model(UrSettings, rig)
    rig.write_text('robot_ip = "10.0.0.5"\nrtde_prot = 30004\n')
    with pytest.raises(ConfigError, match="rtde_prot"):
        load_model(UrSettings, rig)
    with pytest.raises(AddressError, match=r"^rigs/ur\.toml: robot\.robot_ip: 10\.0\.0: "):
        UrRobot(UrSettings(robot_ip="10.0.0"), where="rigs/ur.toml: robot").connect()


def test_fill_command_splits_axes_by_stiffness() -> None:
    names = registers.INPUT_NAMES
    record = Recipe(1, names, tuple(INPUTS[n] for n in names)).empty()
    cmd = command()
    cmd.stiffness_npm_nmprad[:] = [0, 2000, 0, 200, 200, 0]
    mode = registers.fill_command(
        record, 2**31 + 5, cmd, np.eye(4), stiffness_max=0.0,
        speed_limits=np.full(6, 9.0), deviation_limits=np.full(6, 1.0), damping=0.1,
        gain_scaling=0.5, lookahead_s=0.05, servo_gain=500)
    assert mode == Mode.FORCE and record[registers.SELECTION] == 0b100101
    assert record[registers.SEQ] == 5  # wraps within int32
    assert [record[n] for n in registers.WRENCH] == [1.0, 0, -3.0, 0, 0, 0.3]
    assert [record[n] for n in registers.LIMITS] == [9.0, 1.0, 9.0, 1.0, 1.0, 9.0]
    np.testing.assert_allclose([record[n] for n in registers.POSE],
                               [0.45, 0.12, 0.25, math.pi, 0, 0], atol=1e-12)
    back = registers.pose_matrix(np.array([record[n] for n in registers.POSE]))
    np.testing.assert_allclose(back, cmd.pose_m, atol=1e-12)


def test_ur5e_forward_kinematics_at_zero_is_the_stretched_arm() -> None:
    # all joints 0: the arm lies along -x (a2 + a3), the wrist offsets d4 + d6
    # along -y, and the base height d1 less d5 in z (UR's zero configuration)
    pose = UR5E.flange_pose(np.zeros(6))
    np.testing.assert_allclose(pose[:3, 3], [-0.425 - 0.3922, -(DH_D_M[3] + DH_D_M[5]),
                                             DH_D_M[0] - DH_D_M[4]], atol=1e-12)
    np.testing.assert_allclose(np.abs(np.linalg.det(pose[:3, :3])), 1.0)


def test_the_script_reads_the_registers_the_driver_writes() -> None:
    text = control_script()

    def offset(name: str) -> int:
        return int(name.rsplit("_", 1)[1]) - registers.BASE

    calls = {"force_mode_set_damping": registers.DAMPING,
             "force_mode_set_gain_scaling": registers.GAIN_SCALING}
    for call, name in calls.items():
        assert f"{call}(reg({offset(name)}))" in text
    assert f"six({offset(registers.WRENCH[0])}), 2, six({offset(registers.LIMITS[0])})" in text
    assert (f"reg({offset(registers.LOOKAHEAD)}), reg({offset(registers.SERVO_GAIN)}))"
            in text)
    pose = ", ".join(f"reg({offset(n)})" for n in registers.POSE)
    assert f"target = p[{pose}]" in text
    for name in (registers.SEQ, registers.MODE, registers.SELECTION):
        at = f"B + {offset(name)}" if offset(name) else "B"
        assert f"read_input_integer_register({at})" in text
    assert "write_output_integer_register(B, seq)" in text and offset(registers.APPLIED_SEQ) == 0
    assert offset(registers.SCRIPT_STATE) == 1
    for state in registers.ScriptState:
        if state != registers.ScriptState.NOT_RUNNING:
            assert f"write_output_integer_register(B + 1, {int(state)})" in text


@pytest.mark.parametrize(("source", "first"), [("tcp_force", [0, -1, 5, 0, 0, 0]),
                                                ("ft_raw", [0, 1, 2, 3, 4, 5])])
def test_the_robots_wrench_is_an_ft_source(fake: Any, source: str, first: list[float]) -> None:
    _ur, srv = fake
    robot = robot_for(srv)
    sensor = UrWrenchSensor(robot, source)  # type: ignore[arg-type]
    with robot, sensor:
        states = robot.measurements()
        stamps = []
        for _ in range(4):
            stamps.append(next(states).time_ns)
            robot.send(None)
        got = sensor.samples()
        assert list(got.time_ns) == stamps and list(got.seq) == [0, 1, 2, 3]
        np.testing.assert_allclose(got.wrench, np.tile(first, (4, 1)), atol=1e-12)
        sensor.tare()
        next(states)
        np.testing.assert_allclose(sensor.samples().wrench, np.zeros((1, 6)), atol=1e-12)
        assert len(sensor.samples()) == 0


def test_a_nan_command_never_reaches_the_robot(fake: Any) -> None:
    ur, srv = fake
    with robot_for(srv) as robot:
        next(robot.measurements())
        cmd = command()
        cmd.wrench_n_nm[2] = float("nan")
        with pytest.raises(PacketEncodeError, match="input_double_register_32: NaN"):
            robot.send(cmd)
    assert ur.ended.wait(10.0)  # close() still ended the program, with a clean command
    assert all(math.isfinite(ur.inputs[n]) for n in registers.WRENCH)


def test_a_controller_that_stops_sending_is_a_timeout_naming_the_address() -> None:
    ur = FakeUr()
    with RtdeServer(ur.source, ur.sink, host=HOST, port=0, pacing="lockstep",
                    outputs=OUTPUT_NAMES, lockstep_timeout_s=30.0) as srv:
        robot = UrRobot(UrSettings(robot_ip=HOST, rtde_port=srv.port, script="installed",
                                   connect_timeout_s=5.0, cycle_timeout_s=0.2))
        with robot:
            states = robot.measurements()
            next(states)  # not answered: the lockstep controller waits for the answer
            with pytest.raises(DriverTimeoutError, match=rf"^{HOST}:{srv.port}: .*0.2 s"):
                next(states)
