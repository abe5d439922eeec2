"""The RTDE client against stand-in controllers (one per error) and against our RTDE server.

Each stand-in is a scripted TCP peer on 127.0.0.1 in a thread. Every wait is a
socket read with a deadline of seconds: a stall only slows a test down.
"""

from __future__ import annotations

import itertools
import math
import socket
import struct
import threading
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest

from drivers.errors import (
    AddressError,
    DriverTimeoutError,
    LinkLostError,
    MalformedPacketError,
    NotConnectedError,
)
from drivers.ur.emulate.rtde_server import RtdeFaults, RtdeServer
from drivers.ur.errors import RtdeRefusedError
from drivers.ur.rtde import codec
from drivers.ur.rtde.client import RtdeClient
from drivers.ur.rtde.codec import PackageType

HOST = "127.0.0.1"
ACCEPT = codec.encode(codec.Accepted(PackageType.REQUEST_PROTOCOL_VERSION, True))
OUT_REPLY = codec.encode(codec.RecipeReply(PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS, 1,
                                           ("DOUBLE",)))
START_OK = codec.encode(codec.Accepted(PackageType.CONTROL_PACKAGE_START, True))


def data(stamp: float) -> bytes:
    return codec.package(PackageType.DATA_PACKAGE, b"\x01" + struct.pack(">d", stamp))


class StandIn:
    """A controller that answers each request with the next scripted reply (bytes, or a
    callable doing anything with the socket), then runs ``after`` once the script ends."""

    def __init__(self, replies: list[bytes | Callable[[socket.socket], None]],
                 after: Callable[[socket.socket], None] | None = None) -> None:
        self.replies = replies
        self.after = after
        self.listener = socket.socket()
        self.listener.bind((HOST, 0))
        self.listener.listen(1)
        self.port = self.listener.getsockname()[1]
        self.requests: list[int] = []
        self.done = threading.Event()
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    def run(self) -> None:
        self.listener.settimeout(10.0)
        conn, _ = self.listener.accept()
        conn.settimeout(10.0)
        try:
            for reply in self.replies:
                head = conn.recv(3, socket.MSG_WAITALL)
                if len(head) < 3:
                    return
                size, ptype = struct.unpack(">HB", head)
                if size > 3:
                    conn.recv(size - 3, socket.MSG_WAITALL)
                self.requests.append(ptype)
                if callable(reply):
                    reply(conn)
                else:
                    conn.sendall(reply)
            if self.after is not None:
                self.after(conn)
            self.done.wait(10.0)
        finally:
            conn.close()
            self.listener.close()

    def close(self) -> None:
        self.done.set()
        self.thread.join(10.0)


@pytest.fixture
def stand_in() -> Iterator[Callable[..., StandIn]]:
    made: list[StandIn] = []

    def make(replies: list[Any], after: Any = None) -> StandIn:
        made.append(StandIn(replies, after))
        return made[-1]

    yield make
    for s in made:
        s.close()


def streaming(stand_in: Callable[..., StandIn], after: Callable[[socket.socket], None]
              ) -> tuple[RtdeClient, str]:
    s = stand_in([ACCEPT, OUT_REPLY, START_OK], after)
    client = RtdeClient(HOST, s.port, timeout_s=5.0)
    client.connect()
    client.setup_outputs(["timestamp"], 500.0)
    client.start()
    return client, f"{HOST}:{s.port}"


# ----------------------------------------------------------------------------- errors


def test_a_controller_that_never_answers_is_a_timeout_naming_the_address(stand_in: Any) -> None:
    s = stand_in([lambda conn: None])
    client = RtdeClient(HOST, s.port, timeout_s=0.2)
    with pytest.raises(DriverTimeoutError, match=rf"^{HOST}:{s.port}: .*sent nothing for 0.2 s"):
        client.connect()
    assert not client.is_open and s.requests == [PackageType.REQUEST_PROTOCOL_VERSION]


def test_a_refused_protocol_version_says_so_with_the_controllers_words(stand_in: Any) -> None:
    refuse = codec.encode(codec.TextMessage("only version 1", "RTDE", 1)) + codec.encode(
        codec.Accepted(PackageType.REQUEST_PROTOCOL_VERSION, False))
    s = stand_in([refuse])
    client = RtdeClient(HOST, s.port, timeout_s=5.0)
    with pytest.raises(RtdeRefusedError) as err:
        client.connect()
    assert str(err.value) == (f"{HOST}:{s.port}: RTDE controller refused protocol version 2: "
                              "the controller does not speak it (controller said: only version 1)")
    assert not client.is_open


def test_not_found_variables_are_named(stand_in: Any) -> None:
    reply = codec.encode(codec.RecipeReply(PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS, 0,
                                           ("DOUBLE", "NOT_FOUND", "NOT_FOUND")))
    s = stand_in([ACCEPT, reply])
    client = RtdeClient(HOST, s.port, timeout_s=5.0)
    client.connect()
    with pytest.raises(RtdeRefusedError, match=rf"^{HOST}:{s.port}: .*NOT_FOUND: aq, bq$") as err:
        client.setup_outputs(["timestamp", "aq", "bq"], 500.0)
    assert err.value.names == ("aq", "bq") and client.output_recipes == {}


def test_a_package_cut_short_by_a_close_is_truncated(stand_in: Any) -> None:
    def half(conn: socket.socket) -> None:
        conn.sendall(data(1.0) + data(2.0)[:7])
        conn.shutdown(socket.SHUT_WR)

    client, where = streaming(stand_in, half)
    assert client.receive().record["timestamp"] == 1.0
    with pytest.raises(MalformedPacketError, match=rf"^{where}: malformed packet \(truncated\): "
                       r"connection closed after 7 of 12 bytes"):
        client.receive()
    assert not client.is_open


def test_a_data_package_shorter_than_its_recipe_is_truncated(stand_in: Any) -> None:
    short = codec.package(PackageType.DATA_PACKAGE, b"\x01" + bytes(4))
    client, where = streaming(stand_in, lambda conn: conn.sendall(short))
    with pytest.raises(MalformedPacketError, match=rf"^{where}: .*\(truncated\): .*4 field bytes"):
        client.receive()


def test_a_data_package_longer_than_its_recipe_is_oversized(stand_in: Any) -> None:
    long = codec.package(PackageType.DATA_PACKAGE, b"\x01" + bytes(9))
    client, where = streaming(stand_in, lambda conn: conn.sendall(long))
    with pytest.raises(MalformedPacketError, match=rf"^{where}: .*\(oversized\)"):
        client.receive()


def test_a_package_that_stops_midway_is_truncated_at_the_timeout(stand_in: Any) -> None:
    client, where = streaming(stand_in, lambda conn: conn.sendall(data(3.0)[:5]))
    with pytest.raises(MalformedPacketError, match=rf"^{where}: .*5 of 12 bytes .* nothing for"):
        client.receive(timeout_s=0.2)


def test_a_close_mid_stream_is_a_lost_link_after_the_packages_before_it(stand_in: Any) -> None:
    def three_then_close(conn: socket.socket) -> None:
        conn.sendall(data(1.0) + data(2.0) + data(3.0))
        conn.shutdown(socket.SHUT_WR)

    client, where = streaming(stand_in, three_then_close)
    assert [client.receive().record["timestamp"] for _ in range(3)] == [1.0, 2.0, 3.0]
    with pytest.raises(LinkLostError, match=rf"^{where}: RTDE controller closed the connection"):
        client.receive()
    assert client.received == 3 and not client.is_open


def test_receive_latest_skips_what_a_slow_reader_missed_and_counts_it(stand_in: Any) -> None:
    def five(conn: socket.socket) -> None:
        conn.sendall(b"".join(data(float(k)) for k in range(1, 6)))

    client, _where = streaming(stand_in, five)
    stamps = []
    while not stamps or stamps[-1] < 5.0:
        stamps.append(float(client.receive_latest().record["timestamp"]))
    assert stamps == sorted(stamps) and client.received == 5
    assert client.skipped == 5 - len(stamps)


def test_nobody_listening_is_a_lost_link_naming_the_address() -> None:
    s = socket.socket()
    s.bind((HOST, 0))
    port = s.getsockname()[1]
    s.close()
    with pytest.raises(LinkLostError, match=rf"^{HOST}:{port}: cannot connect"):
        RtdeClient(HOST, port, timeout_s=2.0).connect()


def test_methods_need_a_connection() -> None:
    with pytest.raises(NotConnectedError, match="RTDE client: receive"):
        RtdeClient(HOST).receive()


# ----------------------------------------------------------------------------- our server


class Pattern:
    """A data source whose every value tells its step k (so a reader can check it)."""

    def __init__(self) -> None:
        self.k = -1

    def __call__(self) -> dict[str, object]:
        self.k += 1
        return pattern(self.k)


def pattern(k: int) -> dict[str, object]:
    return {"timestamp": k * 0.002, "actual_q": k + np.arange(6) / 8,
            "actual_TCP_pose": np.array([0.4, 0.1, 0.3, 0.0, 3.1, 0.0]) + k * 1e-4,
            "actual_TCP_force": -np.arange(6) - k * 0.5, "robot_mode": 7,
            "safety_status_bits": 1, "runtime_state": 2}


@pytest.fixture
def server() -> Iterator[RtdeServer]:
    got: list[dict[str, Any]] = []
    srv = RtdeServer(Pattern(), lambda v: got.append(dict(v)), host=HOST, port=0,
                     pacing="lockstep", outputs=pattern(0).keys())
    srv.received_inputs = got  # type: ignore[attr-defined]
    with srv:
        yield srv


def test_lockstep_answers_act_on_the_next_package(server: RtdeServer) -> None:
    with RtdeClient(HOST, server.port, timeout_s=5.0) as client:
        assert str(client.controller_version()) == "5.15.0.0"
        out = client.setup_outputs(["timestamp", "actual_q", "actual_TCP_force",
                                    "input_int_register_0", "safety_status_bits"], 500.0)
        assert out.types == ("DOUBLE", "VECTOR6D", "VECTOR6D", "INT32", "UINT32")
        inp = client.setup_inputs(["input_int_register_0", "input_double_register_24"])
        client.start()
        for k in range(50):
            rec = client.receive().record
            want = pattern(k)
            assert rec["timestamp"] == want["timestamp"]
            np.testing.assert_array_equal(rec["actual_q"], want["actual_q"])
            np.testing.assert_array_equal(rec["actual_TCP_force"], want["actual_TCP_force"])
            assert rec["input_int_register_0"] == (k - 1 if k else 0)  # the answer to k - 1
            client.send(inp, {"input_int_register_0": k, "input_double_register_24": k / 2})
        client.pause()
    got = server.received_inputs  # type: ignore[attr-defined]
    assert [g["input_int_register_0"] for g in got] == list(range(50))
    assert got[-1]["input_double_register_24"] == 24.5
    assert server.counters["lockstep_misses"] == 0


def test_output_frequency_below_the_base_rate_takes_every_nth_step(server: RtdeServer) -> None:
    with RtdeClient(HOST, server.port, timeout_s=5.0) as client:
        client.setup_outputs(["timestamp"], 125.0)
        client.start()
        stamps = [client.receive().record["timestamp"] for _ in range(5)]
    assert np.allclose(np.diff(stamps), 4 * 0.002, rtol=0, atol=1e-12)


def test_a_frequency_that_does_not_divide_the_base_rate_keeps_its_average(
        server: RtdeServer) -> None:
    with RtdeClient(HOST, server.port, timeout_s=5.0) as client:
        client.setup_outputs(["timestamp"], 300.0)
        client.start()
        steps = [round(client.receive().record["timestamp"] / 0.002) for _ in range(30)]
    # the n-th package (from 1) goes at the first step k with floor((k + 1) * 0.6) == n
    assert steps == [math.ceil(n / 0.6 - 1e-9) - 1 for n in range(1, 31)]


def test_the_server_refuses_unknown_and_held_variables(server: RtdeServer) -> None:
    with RtdeClient(HOST, server.port, timeout_s=5.0) as a, \
            RtdeClient(HOST, server.port, timeout_s=5.0) as b:
        with pytest.raises(RtdeRefusedError, match="NOT_FOUND: actual_qq") as err:
            a.setup_outputs(["timestamp", "actual_qq"], 500.0)
        assert "controller said: output recipe has unknown" in str(err.value)
        with pytest.raises(RtdeRefusedError, match="NOT_FOUND: target_q"):  # not served
            a.setup_outputs(["target_q"], 500.0)
        with pytest.raises(RtdeRefusedError, match="recipe id 0"):
            a.setup_outputs(["timestamp"], 501.0)
        a.setup_inputs(["input_int_register_0"])
        held = r"IN_USE: input_int_register_0 \(controller said"
        with pytest.raises(RtdeRefusedError, match=held):
            b.setup_inputs(["input_double_register_0", "input_int_register_0"])
        b.setup_inputs(["input_double_register_0"])
        with pytest.raises(RtdeRefusedError, match="IN_USE: input_double_register_0"):
            a.setup_inputs(["input_double_register_0"])


def test_held_inputs_are_released_when_their_client_leaves(server: RtdeServer) -> None:
    with RtdeClient(HOST, server.port, timeout_s=5.0) as a:
        a.setup_inputs(["input_bit_register_64"])
    with RtdeClient(HOST, server.port, timeout_s=5.0) as b:
        for _ in range(1000):  # until the server has seen a's close (bounded, no sleep)
            try:
                recipe = b.setup_inputs(["input_bit_register_64"])
                break
            except RtdeRefusedError:
                b.controller_version()  # one round trip lets the server read a's close
        assert recipe.types == ("BOOL",)


def test_text_messages_and_malformed_packages_reach_the_server(server: RtdeServer) -> None:
    with RtdeClient(HOST, server.port, timeout_s=5.0) as client:
        client.send_message("hello controller", "test", codec.MessageLevel.WARNING)
        assert client._sock is not None
        client._sock.sendall(codec.package(ord("X")))
        client.controller_version()  # answered after both, in order
        assert server.messages[-1] == codec.TextMessage("hello controller", "test", 2)
        assert server.counters["rejected"] == 1
        assert "unknown_type" in client.messages[-1].message


def test_our_server_refuses_a_protocol_version_it_does_not_speak(server: RtdeServer) -> None:
    client = RtdeClient(HOST, server.port, timeout_s=5.0)
    with pytest.raises(RtdeRefusedError, match="refused protocol version 1"):
        client.connect(protocol_version=1)
    with client:
        assert client.is_open  # version 2 is fine


def test_a_server_port_in_use_is_an_address_error(server: RtdeServer) -> None:
    where = rf"RtdeServer.host: {HOST}:{server.port}: cannot listen"
    with pytest.raises(AddressError, match=where):
        RtdeServer(Pattern(), host=HOST, port=server.port).start()


def test_realtime_pacing_streams_and_pause_stops_it() -> None:
    with RtdeServer(Pattern(), host=HOST, port=0, pacing="realtime",
                    outputs=["timestamp"]) as srv, \
            RtdeClient(HOST, srv.port, timeout_s=5.0) as client:
        client.setup_outputs(["timestamp"], 500.0)
        client.start()
        stamps = [client.receive().record["timestamp"] for _ in range(20)]
        client.pause()
        client.start()
        later = client.receive().record["timestamp"]
    assert np.all(np.diff(stamps) > 0) and later > stamps[-1]


def test_lost_packages_are_exactly_the_gaps_the_client_sees() -> None:
    faults = RtdeFaults(loss=0.3, seed=4)
    with RtdeServer(Pattern(), host=HOST, port=0, pacing="lockstep", outputs=["timestamp"],
                    faults=faults) as srv, \
            RtdeClient(HOST, srv.port, timeout_s=5.0) as client:
        client.setup_outputs(["timestamp"], 500.0)
        client.start()
        steps = [round(client.receive().record["timestamp"] / 0.002) for _ in range(60)]
        dropped = set(srv.dropped_steps)  # every drop before the last step read is in it
    gaps = {k for a, b in itertools.pairwise(steps) for k in range(a + 1, b)}
    assert gaps == {k for k in dropped if steps[0] < k < steps[-1]} and not gaps & set(steps)
    assert set(range(steps[0])) <= dropped  # the first steps, if lost
    assert len(gaps) >= 10  # a 30 % loss over 60 packages


def test_a_delayed_stream_keeps_every_package_in_order() -> None:
    with RtdeServer(Pattern(), host=HOST, port=0, pacing="realtime", outputs=["timestamp"],
                    faults=RtdeFaults(delay_s=0.01)) as srv, \
            RtdeClient(HOST, srv.port, timeout_s=5.0) as client:
        client.setup_outputs(["timestamp"], 500.0)
        client.start()
        stamps = [client.receive().record["timestamp"] for _ in range(20)]
        assert srv.counters["faults_delayed"] >= 20
    steps = np.round(np.array(stamps) / 0.002)
    assert np.all(np.diff(steps) >= 1)


def test_an_injected_disconnect_is_a_lost_link_after_that_many_packages() -> None:
    with RtdeServer(Pattern(), host=HOST, port=0, pacing="lockstep", outputs=["timestamp"],
                    faults=RtdeFaults(disconnect_after=7)) as srv, \
            RtdeClient(HOST, srv.port, timeout_s=5.0) as client:
        client.setup_outputs(["timestamp"], 500.0)
        client.start()
        for _ in range(7):
            client.receive()
        with pytest.raises(LinkLostError, match=rf"^{HOST}:{srv.port}: "):
            client.receive()
    assert srv.counters["faults_disconnected"] == 1
