"""The FRI remote driver against a scripted KRC on loopback (no emulator, no simulator).

Every wait is a socket read with a timeout or the driver's own condition
variable; nothing sleeps.
"""

from __future__ import annotations

import socket
from collections.abc import Iterator

import numpy as np
import pytest

from drivers.base.types import ApplyStatus, CartesianCommand, RobotState
from drivers.errors import AddressError, NotConnectedError, PacketEncodeError
from drivers.fri import codec
from drivers.fri.backend import FriRobotConfig
from drivers.fri.command import CARTESIAN_FLAGS, MIRROR_FLAGS
from drivers.fri.convert import LOCKSTEP_INDEX, LOCKSTEP_MARKER, measurement_to_arrays
from drivers.fri.driver import FriEstimateSensor, FriRobot
from drivers.fri.types import ControlMode, FriCommand, FriMeasurement, FriQuality, FriState
from drivers.net.udp import bind_udp, parse_host_port

LOCAL = "127.0.0.1"


class Krc:
    """A scripted KRC: sends measurements to the driver, reads its answers."""

    def __init__(self, dest: tuple[str, int]) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((LOCAL, 0))
        self.sock.settimeout(5.0)
        self.dest = dest
        self.arrays = codec.MsrArrays()

    def send(self, m: FriMeasurement, seq: int) -> None:
        measurement_to_arrays(m, self.arrays)
        self.arrays.send_seq = seq & 0xFFFF
        self.sock.sendto(codec.encode_msr(self.arrays), self.dest)

    def answer(self) -> codec.CmdArrays:
        data, _ = self.sock.recvfrom(2048)
        a = codec.CmdArrays()
        assert codec.decode_cmd_into(data, a) is codec.DecodeStatus.OK
        return a

    def silent(self, timeout_s: float = 0.05) -> bool:
        self.sock.settimeout(timeout_s)
        try:
            self.sock.recvfrom(2048)
        except TimeoutError:
            return True
        finally:
            self.sock.settimeout(5.0)
        return False


def msr(state: FriState = FriState.CMD, lockstep: bool = True, **kw: object) -> FriMeasurement:
    m = FriMeasurement(state=state, control=ControlMode.CART_IMPEDANCE, **kw)  # type: ignore[arg-type]
    m.msr_sample_time = m.cmd_sample_time = 0.002
    m.cmd_jnt_pos[:] = np.linspace(0.1, 0.7, 7)
    m.cmd_cart_pos[:3, 3] = [0.5, 0.0, 0.4]
    m.msr_cart_pos[:3, 3] = [0.5, 0.001, 0.4]
    m.est_ext_tcp_ft[:] = [0.0, 0.0, -2.0, 0.0, 0.0, 0.0]
    if lockstep:
        m.krl_int[LOCKSTEP_INDEX] = LOCKSTEP_MARKER
    return m


def cart() -> CartesianCommand:
    c = CartesianCommand()
    c.pose_m[:3, 3] = [0.5, 0.0, 0.41]
    c.stiffness_npm_nmprad[:] = [2000, 2000, 500, 200, 200, 200]
    c.damping_ratio[:] = 0.7
    c.wrench_n_nm[:] = [0, 0, 3.0, 0, 0, 0]
    return c


@pytest.fixture
def link(request: pytest.FixtureRequest) -> Iterator[tuple[FriRobot, Krc]]:
    kw = getattr(request, "param", {})
    robot = FriRobot(FriRobotConfig(robot_ip=LOCAL, port=0, bind_host=LOCAL, **kw))
    krc = Krc(robot.bind())
    robot.connect()
    try:
        yield robot, krc
    finally:
        robot.close()
        krc.sock.close()


def test_lockstep_cycle_mirror_then_cartesian(link: tuple[FriRobot, Krc]) -> None:
    robot, krc = link
    states = robot.measurements()
    # monitor mode: the runner's command is mirrored
    krc.send(msr(FriState.MON), 7)
    s = next(states)
    assert isinstance(s, RobotState) and isinstance(s.extras, FriMeasurement)
    assert not s.link.commanding and s.link.healthy and s.link.cycle == 7
    assert s.link.cycle_s == pytest.approx(0.002) and s.truth is None
    np.testing.assert_array_equal(s.tcp_pose_m, s.extras.msr_cart_pos)
    applied = robot.send(cart())
    assert applied.status is ApplyStatus.MIRRORED
    a = krc.answer()
    assert a.cmd_flags == MIRROR_FLAGS and a.refl_seq == 7 and a.send_seq == 0
    np.testing.assert_allclose(a.jnt_pos, np.linspace(0.1, 0.7, 7), atol=1e-7)
    np.testing.assert_allclose(a.cart_pos[:3, 3], [0.5, 0.0, 0.4], atol=1e-7)
    np.testing.assert_array_equal(applied.command.pose_m, a.cart_pos)
    assert not applied.command.wrench_n_nm.any()
    # command mode: the Cartesian command as given
    krc.send(msr(FriState.CMD), 8)
    s = next(states)
    assert s.link.commanding and s.time_ns == 2_000_000  # time 0 is the first packet
    c = cart()
    applied = robot.send(c)
    c.wrench_n_nm[:] = 99.0  # the caller reuses its object: the driver copied
    assert applied.status is ApplyStatus.APPLIED
    a = krc.answer()
    assert a.cmd_flags == CARTESIAN_FLAGS and a.refl_seq == 8 and a.send_seq == 1
    np.testing.assert_allclose(a.add_tcp_ft, [0, 0, 3.0, 0, 0, 0], atol=1e-6)
    np.testing.assert_allclose(a.cart_stiffness, [2000, 2000, 500, 200, 200, 200])
    assert int(a.krl_int[0]) == 20  # strategy request: Cartesian impedance
    assert isinstance(applied.extras, FriCommand)
    assert applied.extras.flags == CARTESIAN_FLAGS
    np.testing.assert_allclose(applied.command.wrench_n_nm, [0, 0, 3.0, 0, 0, 0])
    st = robot.stats
    assert (st.accepted, st.runner_answers, st.deadline_answers, st.runner_late) == (2, 2, 0, 0)
    assert st.state is FriState.CMD and not st.link_lost


@pytest.mark.parametrize("link", [{"answer_deadline_cycles": 0.5}], indirect=True)
def test_a_late_runner_is_answered_at_the_deadline_and_told(link: tuple[FriRobot, Krc]) -> None:
    robot, krc = link
    states = robot.measurements()
    krc.send(msr(FriState.CMD, lockstep=False), 1)
    a = krc.answer()  # nobody sent anything: the KRC is held where it is
    assert a.cmd_flags == MIRROR_FLAGS
    next(states)
    applied = robot.send(cart())
    assert applied.status == ApplyStatus.APPLIED | ApplyStatus.LATE
    assert krc.silent()  # the late command is not sent for the past cycle ...
    krc.send(msr(FriState.CMD, lockstep=False), 2)
    a = krc.answer()  # ... but at the next deadline
    assert a.cmd_flags == CARTESIAN_FLAGS and a.refl_seq == 2
    np.testing.assert_allclose(a.cart_pos[:3, 3], [0.5, 0.0, 0.41], atol=1e-7)
    # the link drops to monitor mode and the runner is late again: re-mirrored
    next(states)
    robot.send(cart())
    krc.send(msr(FriState.MON, lockstep=False), 3)
    assert krc.answer().cmd_flags == MIRROR_FLAGS
    st = robot.stats
    assert st.deadline_answers == 3 and st.runner_late == 2 and st.fallbacks == 1
    assert st.link_lost and len(robot.turnarounds_ns()) == 3


@pytest.mark.parametrize("link", [{"answer_deadline_cycles": 0.0}], indirect=True)
def test_deadline_zero_answers_on_arrival_with_the_latest_command(
    link: tuple[FriRobot, Krc],
) -> None:
    robot, krc = link
    states = robot.measurements()
    krc.send(msr(lockstep=False), 1)
    assert krc.answer().cmd_flags == MIRROR_FLAGS
    next(states)
    assert robot.send(cart()).status is ApplyStatus.APPLIED  # by design, not LATE
    krc.send(msr(lockstep=False), 2)
    assert krc.answer().cmd_flags == CARTESIAN_FLAGS
    next(states)
    assert robot.send(None).status is ApplyStatus.HELD
    krc.send(msr(lockstep=False), 3)
    assert krc.answer().cmd_flags == MIRROR_FLAGS


def test_duplicates_gaps_stale_and_foreign(link: tuple[FriRobot, Krc]) -> None:
    robot, krc = link
    states = robot.measurements()
    krc.send(msr(), 0xFFFE)
    next(states)
    robot.send(cart())
    first = krc.answer()
    krc.send(msr(), 0xFFFE)  # duplicate: the same reply again, not passed on
    again = krc.answer()
    assert again.send_seq == first.send_seq and again.refl_seq == 0xFFFE
    krc.send(msr(), 0xFFFE - 3)  # older: dropped silently
    assert krc.silent()
    foreign = bind_udp("test", "127.0.0.2", 0)
    try:
        foreign.sendto(codec.encode_msr(krc.arrays), krc.dest)
    finally:
        foreign.close()
    krc.send(msr(), 2)  # wraps: 0xFFFF, 0, 1 lost
    s = next(states)
    assert s.link.cycle == 0xFFFE + 4 and s.time_ns == 4 * 2_000_000
    robot.send(cart())
    assert krc.answer().refl_seq == 2
    st = robot.stats
    assert (st.duplicates, st.stale, st.lost, st.foreign) == (1, 1, 3, 1)
    assert st.answers == 3 and st.decode["ok"] == 4


def test_implausible_measurements_are_dropped(link: tuple[FriRobot, Krc]) -> None:
    robot, krc = link
    m = msr()
    m.msr_sample_time = 0.5
    krc.send(m, 1)
    assert krc.silent()
    assert robot.stats.implausible == 1 and robot.stats.accepted == 0


def test_nan_is_never_put_on_the_wire(link: tuple[FriRobot, Krc]) -> None:
    robot, krc = link
    states = robot.measurements()
    krc.send(msr(), 1)
    next(states)
    bad = cart()
    bad.wrench_n_nm[2] = np.nan
    with pytest.raises(PacketEncodeError):
        robot.send(bad)
    robot.send(None)
    a = krc.answer()
    assert a.cmd_flags == MIRROR_FLAGS and np.isfinite(a.add_tcp_ft).all()


def test_estimate_sensor_reads_est_ext_tcp_ft(link: tuple[FriRobot, Krc]) -> None:
    robot, krc = link
    sensor = FriEstimateSensor(robot)
    with pytest.raises(NotConnectedError, match="FRI estimate F/T"):
        sensor.samples()
    sensor.start()
    states = robot.measurements()
    for seq in (1, 2):
        krc.send(msr(), seq)
        next(states)
        robot.send(None)
        krc.answer()
    ft = sensor.samples()
    assert ft.seq.tolist() == [1, 2]
    assert ft.time_ns.tolist() == [0, 2_000_000]
    np.testing.assert_allclose(ft.wrench[:, 2], [-2.0, -2.0], atol=1e-6)
    sensor.tare()
    krc.send(msr(), 3)
    next(states)
    robot.send(None)
    krc.answer()
    np.testing.assert_allclose(sensor.samples().wrench, np.zeros((1, 6)), atol=1e-9)


def test_not_connected_and_address_errors() -> None:
    robot = FriRobot(FriRobotConfig(robot_ip=LOCAL, port=0))
    with pytest.raises(NotConnectedError, match=r"FRI robot: send\(\)"):
        robot.send(None)
    with pytest.raises(NotConnectedError, match=r"measurements\(\)"):
        robot.measurements()
    with pytest.raises(
        AddressError, match=r"^rigs/lab\.toml: robot\.robot_ip: 10\.0\.0: not a valid IPv4"
    ):
        FriRobot(FriRobotConfig(robot_ip="10.0.0"), where="rigs/lab.toml: robot")
    taken = bind_udp("test", LOCAL, 0)
    try:
        port = taken.getsockname()[1]
        r = FriRobot(FriRobotConfig(robot_ip=LOCAL, port=port, bind_host=LOCAL))
        with pytest.raises(AddressError, match=rf"^robot\.port: {LOCAL}:{port}: "):
            r.bind()
    finally:
        taken.close()
    with pytest.raises(AddressError, match=r"^rig: ft\.host: 127\.0\.0\.1:c: port 'c' is not a"):
        parse_host_port("rig: ft.host", "127.0.0.1:c")


def test_connect_timeout_names_the_address_and_port() -> None:
    robot = FriRobot(FriRobotConfig(robot_ip=LOCAL, port=0, bind_host=LOCAL,
                                    connect_timeout_s=0.05))
    robot.connect()
    try:
        port = robot.local_address[1]
        with pytest.raises(Exception, match=rf"no FRI measurement from {LOCAL} on UDP port {port}"):
            next(robot.measurements())
    finally:
        robot.close()
    assert robot.stats.quality is FriQuality.INVALID
