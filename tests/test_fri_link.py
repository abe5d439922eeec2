"""FRI over UDP on loopback: the remote driver against the controller emulator, in-process.

Every socket is bound to 127.0.0.1 on an ephemeral port; every thread and
socket is closed in ``finally``. Lockstep tests never wait for wall time;
the real-time test is marked slow.
"""

from __future__ import annotations

import socket
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import fields

import numpy as np
import pytest

from drivers.base.types import CmdFlags, Command, ControlMode, FriQuality, FriState, Measurement
from drivers.errors import AddressError, DriverTimeoutError, LinkLostError, NotConnectedError
from drivers.fri import codec
from drivers.fri.convert import (
    STRATEGY_INDEX,
    arrays_to_command,
    command_to_arrays,
    measurement_to_arrays,
)
from drivers.fri.driver import FriEstimateSensor, FriRobot, FriSettings
from drivers.fri.emulator import (
    EmulatorSettings,
    FaultSettings,
    FriEmulator,
    LinkWindow,
    QualityThresholds,
    quality_of,
)
from drivers.sim.scene import Scene
from drivers.sim.world import SimWorld

LOCAL = "127.0.0.1"


def f32(a: np.ndarray) -> np.ndarray:
    return np.asarray(a, dtype=np.float64).astype(np.float32).astype(np.float64)


@contextmanager
def link(
    scene: Scene,
    *,
    seed: int = 0,
    pacing: str = "lockstep",
    faults: FaultSettings | None = None,
    timeout_s: float = 0.5,
    answer_deadline: float = 0.5,
    cycle_timeout_s: float = 10.0,
) -> Iterator[tuple[FriRobot, FriEmulator]]:
    world = SimWorld(scene, seed=seed)
    robot = FriRobot(
        FriSettings(
            robot_ip=LOCAL, port=0, bind_host=LOCAL, answer_deadline=answer_deadline,
            connect_timeout_s=10.0, cycle_timeout_s=cycle_timeout_s,
        )
    )
    emu: FriEmulator | None = None
    try:
        _, port = robot.bind()
        emu = FriEmulator(
            world,
            EmulatorSettings(
                remote=(LOCAL, port), bind_host=LOCAL,
                pacing="lockstep" if pacing == "lockstep" else "realtime",
                lockstep_timeout_s=timeout_s, faults=faults or FaultSettings(),
            ),
        )
        robot.connect()
        yield robot, emu
    finally:
        if emu is not None:
            emu.close()
        robot.close()


def constant_command() -> Command:
    return Command(
        flags=CmdFlags.CARTSTIFF | CmdFlags.CARTDAMP | CmdFlags.TCPFT,
        control=ControlMode.CART_IMPEDANCE,
        add_tcp_ft=np.array([0.3, -0.2, 2.5, 0.01, 0.02, -0.015]),
        cart_stiffness=np.array([5000.0, 0.0, 0.0, 0.0, 300.0, 300.0]),
        cart_damping=np.array([0.7, 0.0, 0.0, 0.0, 0.7, 0.7]),
    )


def rounded(c: Command) -> Command:
    """What the emulator decodes from the wire: every float rounded to float32."""
    return Command(
        flags=c.flags, control=c.control, jnt_pos=f32(c.jnt_pos), cart_pos=f32(c.cart_pos),
        add_jnt_trq=f32(c.add_jnt_trq), add_tcp_ft=f32(c.add_tcp_ft),
        jnt_stiffness=f32(c.jnt_stiffness), jnt_damping=f32(c.jnt_damping),
        cart_stiffness=f32(c.cart_stiffness), cart_damping=f32(c.cart_damping),
    )


FLOAT_FIELDS = [
    f.name for f in fields(Measurement)
    if f.name not in ("krl_int", "truth") and f.type in ("F64",)
]
INT_FIELDS = ["seq", "time_ns", "control", "power", "error", "warning"]


def run_constant(robot: FriRobot, emu: FriEmulator, cmd: Command, n: int) -> list[Measurement]:
    emu.start_thread(max_cycles=n)
    got: list[Measurement] = []
    for m in robot.measurements():
        got.append(m)
        robot.send(cmd)
        if len(got) == n:
            break
    emu.join(timeout=30.0)
    return got


# --------------------------------------------------------------------------- end to end


@pytest.mark.slow
def test_lockstep_reproduces_the_in_process_run_in_float32(paper_scene: Scene) -> None:
    """10 s of simulated time over UDP equal the in-process run, rounded to float32.

    The comparison run gets the same float32-rounded commands the emulator
    decoded (the constant command once in CMD; the driver's mirror of the
    measured command pose on the cycle that enters CMD) and the same
    interface state per cycle.
    """
    n = 2000  # 10 s at 5 ms
    cmd = constant_command()
    with link(paper_scene, seed=7) as (robot, emu):
        got = run_constant(robot, emu, cmd, n)
        assert emu.stats.missed == 0 and emu.stats.starts == 1
        assert robot.stats.deadline_answers == 0 and robot.stats.skipped == 0
    assert len(got) == n
    states = [m.state for m in got]
    first_cmd = states.index(FriState.CMD)
    assert first_cmd == 100  # m_0..m_99 answered, then friStart; m_100 reports CMD
    assert all(s == FriState.MON for s in states[:first_cmd])
    assert all(s == FriState.CMD for s in states[first_cmd:])
    assert all(m.truth is None for m in got)

    world = SimWorld(paper_scene, seed=7)
    world.fri_state = FriState.MON
    c32 = rounded(cmd)
    ref = [world.last_measurement]
    for k in range(n - 1):
        world.fri_state = got[k + 1].state  # the state during step k
        if got[k].state == FriState.CMD:
            step = c32
        else:  # the driver mirrors the KRC while not commanding
            step = rounded(constant_command())
            step.jnt_pos = f32(got[k].cmd_jnt_pos + got[k].cmd_jnt_pos_fri_offset)
            step.cart_pos = f32(got[k].cmd_cart_pos)
        ref.append(world.step(step))
    for k, (a, b) in enumerate(zip(got, ref, strict=True)):
        for name in FLOAT_FIELDS:
            x, y = getattr(a, name), f32(getattr(b, name))
            assert np.array_equal(x, y), f"cycle {k}: {name}"
        for name in INT_FIELDS:
            assert int(getattr(a, name)) == int(getattr(b, name)), f"cycle {k}: {name}"
    # the run did something: the commanded wrench moved the arm
    assert not np.allclose(got[-1].msr_cart_pos, got[0].msr_cart_pos, atol=1e-4)


def test_mirror_while_monitoring_and_strategy_request(paper_scene: Scene) -> None:
    """In MON the driver answers cmdJntPos + offset and cmdCartPos; krl.intData[0] = 20."""
    cmd = constant_command()
    cmd.cart_pos = np.eye(4)  # far from the robot: must not be sent in MON
    cmd.flags |= CmdFlags.CARTPOS
    with link(paper_scene) as (robot, emu):
        replies: list[codec.CmdArrays] = []
        orig = emu._read_commands

        def spy() -> Command | None:
            c = orig()
            if c is not None:
                a = codec.CmdArrays()
                command_to_arrays(c, a)
                replies.append(a)
            return c

        emu._read_commands = spy  # type: ignore[method-assign]
        got = run_constant(robot, emu, cmd, 20)
    assert all(m.state == FriState.MON for m in got)
    for m, a in zip(got[1:], replies[1:], strict=False):
        assert np.array_equal(a.cart_pos, f32(m.cmd_cart_pos))
        assert np.array_equal(a.jnt_pos, f32(m.cmd_jnt_pos + m.cmd_jnt_pos_fri_offset))
        assert a.krl_int[STRATEGY_INDEX] == 20
        assert np.array_equal(a.add_tcp_ft, f32(cmd.add_tcp_ft))


def test_strategy_index_round_trip() -> None:
    for mode, code in ((ControlMode.JOINT_POSITION, 10), (ControlMode.CART_IMPEDANCE, 20),
                       (ControlMode.JOINT_IMPEDANCE, 30)):
        a = codec.CmdArrays()
        command_to_arrays(Command(control=mode), a)
        raw = codec.encode_cmd(a)
        b = codec.CmdArrays()
        assert codec.decode_cmd_into(raw, b) is codec.DecodeStatus.OK
        assert int(b.krl_int[STRATEGY_INDEX]) == code
        assert arrays_to_command(b, ControlMode.OTHER).control is mode
    b = codec.CmdArrays()  # no request: keep the running strategy
    assert arrays_to_command(b, ControlMode.JOINT_IMPEDANCE).control is ControlMode.JOINT_IMPEDANCE


def test_a_strategy_request_switches_the_emulated_krc(paper_scene: Scene) -> None:
    cmd = Command(flags=CmdFlags.NONE, control=ControlMode.JOINT_IMPEDANCE,
                  jnt_stiffness=np.full(7, 500.0), jnt_damping=np.full(7, 0.7))
    with link(paper_scene) as (robot, emu):
        got = run_constant(robot, emu, cmd, 120)
        assert emu.world.control is ControlMode.JOINT_IMPEDANCE
    assert got[-1].control is ControlMode.JOINT_IMPEDANCE
    assert got[0].control is ControlMode.CART_IMPEDANCE


# --------------------------------------------------------------------------- faults


def cmd_phase(got: list[Measurement]) -> list[Measurement]:
    k = next(i for i, m in enumerate(got) if m.state == FriState.CMD)
    return got[k:]


def test_five_percent_loss_shows_in_the_statistics_and_quality_is_bad(paper_scene: Scene) -> None:
    cmd = constant_command()
    faults = FaultSettings(loss=0.05, seed=3)
    with link(paper_scene, faults=faults, timeout_s=0.01, cycle_timeout_s=0.5) as (robot, emu):
        got = run_constant_tolerant(robot, emu, cmd, 900)
        st = emu.stats
        assert st.dropped_out > 0 and st.dropped_in > 0
        assert 0.04 < st.missed / st.cycles < 0.16
        assert st.bridged == st.missed  # every miss in CMD held the last command
        assert st.fallbacks == 0
        rs = robot.stats
        assert rs.lost == st.dropped_out  # every lost measurement is a sequence gap
        assert not rs.link_lost
    cmd_ms = cmd_phase(got)
    late = cmd_ms[150:]  # a full window of lossy packets
    assert all(m.state == FriState.CMD for m in cmd_ms)
    assert max(m.miss_rate for m in late) > 0.04
    assert all(abs(m.answer_rate + m.miss_rate - 1.0) < 1e-6 for m in late)
    qualities = {m.quality for m in late}
    assert FriQuality.BAD in qualities and FriQuality.UNACCEPTABLE not in qualities
    assert FriQuality.PERFECT not in qualities
    assert late[-1].miss_counter == st.missed


def run_constant_tolerant(
    robot: FriRobot, emu: FriEmulator, cmd: Command, n: int
) -> list[Measurement]:
    """Like run_constant, but the driver may see fewer packets than the emulator sent."""
    emu.start_thread(max_cycles=n)
    got: list[Measurement] = []
    try:
        for m in robot.measurements():
            got.append(m)
            robot.send(cmd)
            if m.seq >= n - 1:
                break
    except LinkLostError:  # the emulator stopped after a lost last packet
        assert emu.stats.cycles >= n - 1
    emu.join(timeout=30.0)
    return got


def test_thirty_percent_loss_drops_to_monitor_and_the_driver_reports_link_lost(
    paper_scene: Scene,
) -> None:
    cmd = constant_command()
    faults = FaultSettings(loss=0.30, seed=5)
    with link(paper_scene, faults=faults, timeout_s=0.01, cycle_timeout_s=0.5) as (robot, emu):
        got = run_constant_tolerant(robot, emu, cmd, 400)
        st = emu.stats
        rs = robot.stats
        assert st.starts == 1 and st.fallbacks >= 1
        assert st.state == FriState.MON
        assert rs.link_lost and rs.fallbacks >= 1
        assert rs.state == FriState.MON
        # no command applied twice: every applied command has its own sequence number
        seqs = list(st.applied_seqs)
        assert len(seqs) == len(set(seqs)) == st.applied
        assert st.applied <= st.answered
    after = cmd_phase(got)
    k = next(i for i, m in enumerate(after) if m.state != FriState.CMD)
    assert all(m.state == FriState.MON for m in after[k:])
    assert any(m.quality in (FriQuality.BAD, FriQuality.UNACCEPTABLE) for m in after[k - 3:])


def test_duplicates_reordering_and_corruption_are_counted_not_applied(paper_scene: Scene) -> None:
    cmd = constant_command()
    faults = FaultSettings(duplicate=0.1, reorder=0.05, corrupt=0.05, seed=11)
    with link(paper_scene, faults=faults, timeout_s=0.02, cycle_timeout_s=0.5) as (robot, emu):
        run_constant_tolerant(robot, emu, cmd, 400)
        st, rs = emu.stats, robot.stats
        assert st.duplicated > 0 and st.reordered > 0 and st.corrupted > 0
        assert rs.duplicates > 0  # re-answered, not passed on
        rejected = sum(v for k, v in rs.decode.items() if k != "ok")
        assert rejected > 0  # damaged headers
        assert rs.decode["ok"] + rejected + rs.foreign == rs.received
        seqs = list(st.applied_seqs)
        assert len(seqs) == len(set(seqs))
        assert st.duplicates > 0  # the second answer to a duplicate is not applied


def test_quality_thresholds() -> None:
    th = QualityThresholds()
    w = LinkWindow()
    assert quality_of(w, 0.005, th, timing=True) is FriQuality.BAD  # nothing seen yet
    for _ in range(50):
        w.add(True, 0.0002)
    assert quality_of(w, 0.005, th, timing=True) is FriQuality.OK  # window not full
    for _ in range(50):
        w.add(True, 0.0002)
    assert quality_of(w, 0.005, th, timing=True) is FriQuality.PERFECT
    w.add(False, 0.0)
    assert quality_of(w, 0.005, th, timing=True) is FriQuality.OK
    for _ in range(9):
        w.add(False, 0.0)
    assert quality_of(w, 0.005, th, timing=True) is FriQuality.BAD
    for _ in range(20):
        w.add(False, 0.0)
    assert quality_of(w, 0.005, th, timing=True) is FriQuality.UNACCEPTABLE
    slow = LinkWindow()
    for _ in range(100):
        slow.add(True, 0.004)  # 0.8 cycles
    assert quality_of(slow, 0.005, th, timing=True) is FriQuality.BAD
    assert quality_of(slow, 0.005, th, timing=False) is FriQuality.PERFECT  # lockstep


# --------------------------------------------------------------------------- driver alone


class FakeKrc:
    """A bare socket that plays the KRC: sends measurement packets, reads answers."""

    def __init__(self, robot_port: int, host: str = LOCAL) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((host, 0))
        self.sock.settimeout(5.0)
        self.dest = (LOCAL, robot_port)
        self.arrays = codec.MsrArrays()
        measurement_to_arrays(Measurement(state=FriState.MON), self.arrays)
        self.arrays.cmd_cart_pos[:] = np.eye(4)
        self.arrays.cmd_jnt_pos[:] = 0.5

    def packet(self, seq: int, state: FriState = FriState.MON) -> bytes:
        self.arrays.send_seq = seq & 0xFFFF
        self.arrays.state = state
        return codec.encode_msr(self.arrays)

    def send(self, data: bytes) -> None:
        self.sock.sendto(data, self.dest)

    def answer(self) -> codec.CmdArrays:
        data, _ = self.sock.recvfrom(2048)
        a = codec.CmdArrays()
        assert codec.decode_cmd_into(data, a) is codec.DecodeStatus.OK
        return a

    def close(self) -> None:
        self.sock.close()


@contextmanager
def driver(**kw: object) -> Iterator[tuple[FriRobot, FakeKrc]]:
    settings = FriSettings(robot_ip=LOCAL, port=0, bind_host=LOCAL, **kw)  # type: ignore[arg-type]
    robot = FriRobot(settings)
    krc: FakeKrc | None = None
    try:
        _, port = robot.bind()
        krc = FakeKrc(port)
        robot.connect()
        yield robot, krc
    finally:
        if krc is not None:
            krc.close()
        robot.close()


def test_a_late_runner_gets_the_last_command_repeated_at_the_deadline() -> None:
    with driver(answer_deadline=0.5) as (robot, krc):
        it = robot.measurements()
        krc.send(krc.packet(10, FriState.CMD))
        m = next(it)
        robot.send(Command(flags=CmdFlags.TCPFT, add_tcp_ft=np.array([0, 0, 1.0, 0, 0, 0])))
        a = krc.answer()
        assert a.refl_seq == 10 and a.add_tcp_ft[2] == 1.0
        krc.send(krc.packet(11, FriState.CMD))
        a = krc.answer()  # nobody calls send(): answered at the deadline (2.5 ms)
        assert a.refl_seq == 11 and a.add_tcp_ft[2] == 1.0 and a.send_seq == 1
        m = next(it)
        robot.send(Command(flags=CmdFlags.TCPFT, add_tcp_ft=np.array([0, 0, 2.0, 0, 0, 0])))
        st = robot.stats
        assert st.deadline_answers == 1 and st.runner_late == 1 and st.runner_answers == 1
        krc.send(krc.packet(12, FriState.CMD))
        m = next(it)
        assert m.seq == 12
        a = krc.answer()  # the late command is the latest one now
        assert a.refl_seq == 12 and a.add_tcp_ft[2] == 2.0


def test_immediate_answers_and_sequence_tracking() -> None:
    with driver(answer_deadline=0.0) as (robot, krc):
        it = robot.measurements()
        krc.send(krc.packet(65534))
        assert krc.answer().refl_seq == 65534
        m0 = next(it)
        krc.send(krc.packet(65534))  # duplicate: answered again, not passed on
        krc.answer()
        krc.send(krc.packet(2))  # wraps; 65535, 0, 1 lost
        assert krc.answer().refl_seq == 2
        krc.send(krc.packet(1))  # reordered (older): dropped
        krc.send(krc.packet(3))
        assert krc.answer().refl_seq == 3
        m1 = next(it)  # the runner was slow: it gets the newest, 2 was skipped
        assert m1.seq - m0.seq == 5
        assert m1.time_ns - m0.time_ns == 5 * 5_000_000
        st = robot.stats
        assert (st.duplicates, st.lost, st.stale, st.skipped) == (1, 3, 1, 1)
        assert st.answers == 4


def test_foreign_senders_are_ignored_and_counted() -> None:
    with driver(answer_deadline=0.0) as (robot, krc):
        other = FakeKrc(krc.dest[1], host="127.0.0.2")
        try:
            other.send(other.packet(1))
            krc.send(krc.packet(5))
            krc.answer()
            it = robot.measurements()
            assert next(it).seq == 5
            assert robot.stats.foreign == 1 and robot.stats.accepted == 1
        finally:
            other.close()


def test_fri_estimate_sensor_reads_est_ext_tcp_ft() -> None:
    with driver(answer_deadline=0.0) as (robot, krc):
        sensor = FriEstimateSensor(robot)
        sensor.start()
        it = robot.measurements()
        for k in range(3):
            krc.arrays.est_ext_tcp_ft[:] = [1.0 + k, 2.0, 3.0, 0.25, 0.5, 0.75]
            krc.send(krc.packet(k))
            krc.answer()
            next(it)
        s = sensor.samples()
        assert len(s) == 3
        assert s.wrench[:, 0].tolist() == [1.0, 2.0, 3.0]
        assert s.wrench[0, 3:].tolist() == [0.25, 0.5, 0.75]
        assert s.time_ns.tolist() == [0, 5_000_000, 10_000_000]
        sensor.tare()
        krc.arrays.est_ext_tcp_ft[:] = [4.0, 2.0, 3.0, 0.25, 0.5, 0.75]
        krc.send(krc.packet(3))
        krc.answer()
        next(it)
        assert np.allclose(sensor.samples().wrench, [[1.0, 0, 0, 0, 0, 0]])


def test_no_robot_is_a_timeout_naming_the_address() -> None:
    with driver(connect_timeout_s=0.2) as (robot, _krc):
        with pytest.raises(DriverTimeoutError, match=r"no FRI packet from 127\.0\.0\.1 on UDP"):
            next(robot.measurements())


def test_use_before_connect_and_bad_addresses() -> None:
    robot = FriRobot(FriSettings(robot_ip=LOCAL, port=0))
    with pytest.raises(NotConnectedError):
        next(robot.measurements())
    with pytest.raises(NotConnectedError):
        robot.send(Command())
    robot.close()
    with pytest.raises(AddressError, match=r"--robot-ip 10\.0\.0"):
        FriRobot(FriSettings(robot_ip="10.0.0"))
    busy = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    busy.bind((LOCAL, 0))
    try:
        port = busy.getsockname()[1]
        r = FriRobot(FriSettings(robot_ip=LOCAL, port=port, bind_host=LOCAL))
        with pytest.raises(AddressError, match=rf"--fri-port 127\.0\.0\.1:{port}: cannot bind"):
            r.connect()
        r.close()
    finally:
        busy.close()


# --------------------------------------------------------------------------- real time


@pytest.mark.slow
def test_real_time_pacing_keeps_the_wall_clock_cycle(paper_scene: Scene) -> None:
    import time

    cmd = constant_command()
    with link(paper_scene, pacing="realtime") as (robot, emu):
        emu.start_thread(max_cycles=400)
        got: list[Measurement] = []
        t0 = time.perf_counter()
        for m in robot.measurements():  # real-time: paced by the emulator's clock
            got.append(m)
            robot.send(cmd)
            if len(got) == 400:
                break
        wall = time.perf_counter() - t0
        emu.join(timeout=30.0)
        st = emu.stats
    # never faster than the wall clock; generous bounds below (two busy shared cores)
    assert 0.95 * 399 * 0.005 <= wall <= 3 * 400 * 0.005
    assert st.missed <= 80
    late = got[200:]
    assert sum(m.quality == FriQuality.UNACCEPTABLE for m in late) < 0.2 * len(late)
    assert 0.0 < float(np.median([m.latency for m in late])) < 0.005
    assert float(np.median([m.answer_rate for m in late])) >= 0.8
