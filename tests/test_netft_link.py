"""Net F/T RDT over UDP on loopback: the client against the emulated box (and the FRI emulator)."""

from __future__ import annotations

import select
import socket
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING

import numpy as np
import pytest
from pydantic import ValidationError

from drivers.base.types import FtSamples, FtStatus
from drivers.emulate.netft_box import NetFtServer
from drivers.errors import AddressError, ConfigError, NotConnectedError
from drivers.netft.backend import NetFtConfig
from drivers.netft.client import NetFtClient
from drivers.netft.codec import Calibration, RdtCommand, encode_rdt, encode_request

if TYPE_CHECKING:
    from drivers.description.scene import Scene

LOCAL = "127.0.0.1"
#: N and N·mm, as many boxes are configured: 1e6 counts/N, 1000 counts/N·mm.
CAL = Calibration.from_unit_codes(1_000_000, 1_000, 2, 4)


def settings(port: int, cal: Calibration = CAL, **kw: object) -> NetFtConfig:
    return NetFtConfig(
        host=LOCAL, port=port, counts_per_force=cal.counts_per_force,
        counts_per_torque=cal.counts_per_torque, force_unit_n=cal.force_unit,
        torque_unit_nm=cal.torque_unit, local_host=LOCAL, **kw,  # type: ignore[arg-type]
    )


@contextmanager
def box_and_client(
    mode: str = "realtime", calibration: Calibration = CAL, buffer_size: int = 10
) -> Iterator[tuple[NetFtServer, NetFtClient, list[int]]]:
    biases: list[int] = []
    server = NetFtServer.open(LOCAL, 0, calibration=calibration, buffer_size=buffer_size,
                              on_bias=lambda: biases.append(1))
    client: NetFtClient | None = None
    try:
        client = NetFtClient(
            settings(server.address[1], calibration,
                     mode="buffered" if mode == "buffered" else "realtime"),
            clock=lambda: 1_000_000_000,
        )
        client.start()
        assert wait_for(server.sock)
        server.handle_requests()
        yield server, client, biases
    finally:
        if client is not None:
            client.stop()
        server.close()


def wait_for(sock: socket.socket | NetFtClient, timeout: float = 5.0) -> bool:
    import select

    r, _, _ = select.select([sock], [], [], timeout)
    return bool(r)


def collect(client: NetFtClient, n: int) -> FtSamples:
    parts: list[FtSamples] = []
    got = 0
    for _ in range(1000):  # bounded
        if got >= n:
            break
        assert client.wait(5.0)
        s = client.samples()
        parts.append(s)
        got += len(s)
    return FtSamples.concat(parts)


def samples(n: int, start: int = 0) -> FtSamples:
    k = np.arange(start, start + n)
    wrench = np.stack(
        [1.5 + k, -2.25 * np.ones(n), 10.0 - k, 0.125 * np.ones(n), -0.5 + 0.001 * k,
         0.03125 * np.ones(n)], axis=1)
    status = np.zeros(n, dtype=np.uint32)
    status[1::3] = FtStatus.SATURATION
    return FtSamples(time_ns=k * 1_000_000, seq=k.astype(np.int64), wrench=wrench, status=status)


def test_values_units_and_status_bits() -> None:
    with box_and_client() as (server, client, _):
        src = samples(7)
        assert server.publish(src) == 7
        got = collect(client, 7)
    assert len(got) == 7
    assert np.allclose(got.wrench, src.wrench, rtol=0, atol=1e-9)
    # status words pass through, with the box's error-summary bit on any error
    assert got.status.tolist() == [0, 0x80020000, 0, 0, 0x80020000, 0, 0]
    assert got.seq.tolist() == list(range(7))
    # stamped from the anchor (the robot's clock) by ft_sequence at 1 kHz
    assert got.time_ns.tolist() == [1_000_000_000 - 6_000_000 + 1_000_000 * i for i in range(7)]
    assert client.stats.lost == 0 and client.stats.records == 7


def test_units_matter_n_mm_read_as_n_m_is_a_thousand_times_too_big() -> None:
    server_cal = CAL
    wrong = Calibration.from_unit_codes(1_000_000, 1_000, 2, 3)  # N·m instead of N·mm
    server = NetFtServer.open(LOCAL, 0, calibration=server_cal)
    client = NetFtClient(settings(server.address[1], wrong))
    try:
        client.start()
        assert wait_for(server.sock)
        server.handle_requests()
        server.publish(samples(1))
        got = collect(client, 1)
        assert got.wrench[0, 3] == pytest.approx(0.125 * 1000)
        assert got.wrench[0, 0] == pytest.approx(1.5)
    finally:
        client.stop()
        server.close()


def test_buffered_mode_packs_records() -> None:
    with box_and_client(mode="buffered", buffer_size=4) as (server, client, _):
        assert server.buffered
        server.publish(samples(10))
        got = collect(client, 10)
        assert server.datagrams == 3
    assert got.seq.tolist() == list(range(10))


def test_sequence_gaps_duplicates_reordering_and_foreign_senders() -> None:
    with box_and_client() as (server, client, _):
        assert server.client is not None
        dest = server.client
        cnt = np.zeros((1, 6), dtype=np.int32)
        send = server.sock.sendto
        send(encode_rdt(10, 100, 0, cnt), dest)
        send(encode_rdt(10, 100, 0, cnt), dest)  # duplicate
        send(encode_rdt(14, 104, 0, cnt), dest)  # 11..13 lost
        send(encode_rdt(12, 102, 0, cnt), dest)  # older: dropped
        other = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            other.bind(("127.0.0.2", 0))
            other.sendto(encode_rdt(15, 105, 0, cnt), client.open())
        finally:
            other.close()
        send(b"\x00" * 35, dest)  # not a multiple of 36
        send(encode_rdt(15, 105, 0, cnt), dest)
        got = collect(client, 3)
        st = client.stats
    assert got.seq.tolist() == [100, 104, 105]
    assert (st.lost, st.duplicates, st.stale, st.foreign) == (3, 1, 1, 1)
    assert st.decode["not_multiple"] == 1


def test_requests_stop_bias_and_finite_bursts() -> None:
    with box_and_client() as (server, client, biases):
        client.tare()
        assert wait_for(server.sock)
        server.handle_requests()
        assert biases == [1]
        # a finite burst of 3 samples
        raw = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            raw.bind((LOCAL, 0))
            raw.sendto(encode_request(RdtCommand.START_REALTIME, 3), server.address)
            raw.sendto(b"\x12\x34\x00\x02", server.address)  # bad request: counted
            assert wait_for(server.sock)
            server.handle_requests()
            assert server.client == raw.getsockname()
            assert server.publish(samples(5)) == 3
            assert server.client is None  # the burst is over
        finally:
            raw.close()
        assert server.bad_requests == 1
    assert server.client is None


def test_client_errors() -> None:
    c = NetFtClient(NetFtConfig(host=LOCAL, port=9))
    with pytest.raises(NotConnectedError):
        c.samples()
    with pytest.raises(NotConnectedError):
        c.tare()
    with pytest.raises(AddressError, match=r"^rigs/lab\.toml: ft\.host: 999\.1\.1\.1: "):
        NetFtClient(NetFtConfig(host="999.1.1.1"), where="rigs/lab.toml: ft")
    with pytest.raises(ConfigError, match=r"^rigs/lab\.toml: ft\.host: required"):
        NetFtClient(NetFtConfig(), where="rigs/lab.toml: ft")
    with pytest.raises(ValidationError, match=r"counts_per_torque"):
        NetFtConfig(host=LOCAL, counts_per_torque=0.0)
    unchecked = NetFtConfig.model_construct(host=LOCAL, counts_per_torque=0.0)
    with pytest.raises(ConfigError, match=r"^ft\.counts_per_torque: must be positive"):
        NetFtClient(unchecked)


def test_the_fri_emulator_serves_the_simulated_sensor(paper_scene: Scene) -> None:
    # the emulator and the simulator are imported here: the client tests above need neither
    from drivers.fri.backend import FriRobotConfig
    from drivers.fri.driver import FriRobot
    from drivers.fri.emulate.server import EmulatorSettings, FriEmulator
    from drivers.world.world import SimWorld

    world = SimWorld(paper_scene, seed=4)
    robot = FriRobot(FriRobotConfig(robot_ip=LOCAL, port=0, bind_host=LOCAL))
    server = NetFtServer.open(LOCAL, 0, on_bias=world.tare_ft)
    emu: FriEmulator | None = None
    client = NetFtClient(settings(server.address[1], Calibration()), clock=robot.now_ns)
    try:
        _, port = robot.bind()
        emu = FriEmulator(world, EmulatorSettings(remote=(LOCAL, port), bind_host=LOCAL,
                                                  pacing="lockstep"), server)
        robot.connect()
        client.start()
        # the box must have the start request before the first cycle streams (no race
        # with the emulator thread on a busy machine)
        ready, _, _ = select.select([server.sock], [], [], 10.0)
        assert ready
        server.handle_requests()
        assert server.client is not None
        emu.start_thread(max_cycles=60)
        got: list[FtSamples] = []
        times = []
        for m in robot.measurements():
            got.append(client.samples())
            times.append(m.time_ns)
            robot.send(None)
            if len(times) == 60:
                break
        emu.join(timeout=30.0)
        if client.wait(1.0):
            got.append(client.samples())
    finally:
        client.stop()
        if emu is not None:
            emu.close()
        else:
            server.close()
        robot.close()
    s = FtSamples.concat(got)
    # 5 samples per 5 ms cycle from the first step on (the request came before it)
    assert len(s) == 5 * 60
    assert np.all(np.diff(s.seq) == 1) and np.all(np.diff(s.time_ns) == 1_000_000)
    assert abs(int(s.time_ns[-1]) - times[-1]) <= 10_000_000
    # the reading contains the tool's weight (about 1 N or more along gravity)
    assert np.linalg.norm(s.wrench[:, :3], axis=1).mean() > 0.5
    assert client.stats.lost == 0 and client.stats.foreign == 0
