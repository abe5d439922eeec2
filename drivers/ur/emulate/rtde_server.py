"""The controller's side of RTDE (protocol version 2) over TCP: a UR controller's port 30004.

:class:`RtdeServer` listens on ``host:port`` (default 127.0.0.1:30004; any
loopback address may be chosen, so that parallel tests each have their own
30004) and serves any number of clients in one thread:

- ``V``: accepts the versions in ``protocol_versions`` (2), refuses others;
  ``v``: answers ``controller_version``;
- ``O``: one output recipe per connection, at a frequency in (0, base_hz];
  a name outside the catalogue (:mod:`drivers.ur.rtde.variables`) or outside
  ``outputs`` is ``NOT_FOUND``; ur_rtde's trailing comma is ignored;
- ``I``: input recipes; an input another connection holds is ``IN_USE``
  (released when that connection closes), an unknown one ``NOT_FOUND``;
  a refused recipe gets id 0 and a text message saying why;
- ``S`` / ``P``: start and pause this connection's stream;
- ``U``: each input package goes to ``sink(values)`` (name -> value, in the
  server's thread) and is kept, so that an output recipe may read inputs
  back (``input_double_register_N`` ...);
- ``M``: kept in :attr:`RtdeServer.messages`.

A *session* starts when a connection starts its stream for the first time
while no other one streams (a pause and a start again is not a new one): the
server then calls ``on_session()`` (if given; the emulated UR
starts its world anew there) and keeps as its inputs only what that
connection has already written, which go to ``sink`` again.

The stream: while at least one connection is started, the server calls
``source()`` once per base cycle (``base_hz``, 500 Hz as an e-Series) and
sends each started connection the package of that step when its frequency
is due: the n-th package of a connection started at step 0 goes at the first
step k with ``floor((k + 1) * f / base_hz) >= n`` (every 4th step at 125 Hz;
at a frequency that does not divide the base rate, the same average). Pacing:

- ``lockstep``: one step right after another, paced only by the source (and,
  with ``lockstep_wait_inputs``, by the clients: a step waits until every
  started connection that holds an input recipe has answered the previous
  package, or ``lockstep_timeout_s``, then counts a miss);
- ``realtime``: one step per period of the wall clock; a step that is due
  more than one period late is skipped and counted (``late_steps``), as a
  busy controller skips packages and sends the newest.

Fault injection (:class:`RtdeFaults`, seeded): output data packages lost or
delayed, the connection closed after a number of them.

Malformed packages are counted (``rejected``) and answered with an error text
message; a header that cannot be framed ends that connection. A value the
source does not give is read from the held inputs or else zero
(``missing_values`` counts those). An exception raised by the source or the
sink ends the server: every connection is dropped (the clients see the link
lost) and the exception is kept in :attr:`RtdeServer.error`.
"""

from __future__ import annotations

import math
import select
import socket
import threading
import time
from collections import Counter, deque
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Final, Literal

import numpy as np

from drivers.errors import AddressError, MalformedPacketError
from drivers.net.udp import parse_port, resolve_ipv4
from drivers.ur.rtde import codec
from drivers.ur.rtde.codec import PackageType
from drivers.ur.rtde.fields import IN_USE, NOT_FOUND, Recipe
from drivers.ur.rtde.variables import INPUTS, OUTPUTS

OutputSource = Callable[[], Mapping[str, object]]
InputSink = Callable[[Mapping[str, Any]], None]
Pacing = Literal["lockstep", "realtime"]

RTDE_PORT: Final = 30004
_IDLE_WAIT_S: Final = 0.05


@dataclass(frozen=True)
class RtdeFaults:
    """Injected faults of the data stream (seeded: the same settings, the same faults).

    ``loss``: each output data package is not sent with this probability (as
    a busy controller skips packages); ``delay_s``: each is sent this long
    after its step (order kept, as on one TCP stream); ``disconnect_after``:
    the connection is closed after this many data packages (0: never).
    """

    loss: float = 0.0
    delay_s: float = 0.0
    disconnect_after: int = 0
    seed: int = 0

    def __post_init__(self) -> None:
        if not 0.0 <= self.loss <= 1.0:
            raise ValueError(f"loss must be a probability in 0..1, got {self.loss}")
        if self.delay_s < 0 or self.disconnect_after < 0:
            raise ValueError("delay_s and disconnect_after must be >= 0")


@dataclass
class _Connection:
    sock: socket.socket
    address: str
    framer: codec.Framer
    output: Recipe | None = None
    output_hz: float = 0.0
    inputs: dict[int, Recipe] = field(default_factory=dict)
    next_id: int = 1
    streaming: bool = False
    started_once: bool = False
    """It has started its stream before (a pause and a start again is the same session)."""
    started_step: int = 0
    answered: bool = True
    data_sent: int = 0
    delayed: deque[tuple[float, bytes]] = field(default_factory=deque)
    written: dict[str, Any] = field(default_factory=dict)
    """The input values this connection has written (a new session keeps these)."""

    def held(self) -> set[str]:
        return {n for r in self.inputs.values() for n in r.names}


class RtdeServer:
    """An RTDE controller endpoint fed by ``source`` (outputs) and feeding ``sink`` (inputs)."""

    def __init__(self, source: OutputSource, sink: InputSink | None = None, *,
                 host: str = "127.0.0.1", port: int = RTDE_PORT,
                 pacing: Pacing = "realtime", base_hz: float = 500.0,
                 outputs: Iterable[str] | None = None,
                 controller_version: tuple[int, int, int, int] = (5, 15, 0, 0),
                 protocol_versions: Iterable[int] = (codec.PROTOCOL_VERSION,),
                 lockstep_wait_inputs: bool = True, lockstep_timeout_s: float = 1.0,
                 faults: RtdeFaults | None = None, where: str = "RtdeServer.host",
                 on_session: Callable[[], None] | None = None) -> None:
        if pacing not in ("lockstep", "realtime"):
            raise ValueError(f"pacing must be lockstep or realtime, not {pacing!r}")
        if not (math.isfinite(base_hz) and base_hz > 0):
            raise ValueError(f"base_hz must be positive, not {base_hz}")
        self.source = source
        self.sink = sink
        self.on_session = on_session
        self.host = resolve_ipv4(where, host)
        self.port = parse_port(where, f"{host}:{port}", port, allow_zero=True)
        self.where = where
        self.pacing: Pacing = pacing
        self.base_hz = base_hz
        self.outputs = frozenset(OUTPUTS if outputs is None else outputs)
        unknown = sorted(self.outputs - OUTPUTS.keys())
        if unknown:
            raise ValueError(f"outputs not in the RTDE catalogue: {', '.join(unknown)}")
        self.controller_version = codec.ControllerVersion(*controller_version)
        self.protocol_versions = frozenset(protocol_versions)
        self.lockstep_wait_inputs = lockstep_wait_inputs
        self.lockstep_timeout_s = lockstep_timeout_s
        self.faults = faults or RtdeFaults()
        self._rng = np.random.default_rng(self.faults.seed)
        self.dropped_steps: list[int] = []
        """The steps whose package a connection did not get (``faults.loss``)."""
        self.counters: Counter[str] = Counter()
        self.messages: deque[codec.TextMessage] = deque(maxlen=100)
        self.inputs: dict[str, Any] = {}
        self.error: BaseException | None = None
        self._conns: dict[socket.socket, _Connection] = {}
        self._listener: socket.socket | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._step = 0
        self._next_due = 0.0
        self._wait_until = 0.0

    # ------------------------------------------------------------------ life cycle

    @property
    def address(self) -> tuple[str, int]:
        """The bound (host, port); the port is the real one when 0 was asked for."""
        return self.host, self.port

    def start(self, thread: bool = True) -> RtdeServer:
        """Bind and listen (:class:`~drivers.errors.AddressError` naming the address),
        then serve in a daemon thread (``thread=False``: only when :meth:`serve_in_thread`
        is called, from the thread whose scheduling, e.g. ``--rt``, it should take)."""
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            sock.bind((self.host, self.port))
            sock.listen(8)
        except OSError as exc:
            sock.close()
            raise AddressError(self.where, f"{self.host}:{self.port}",
                               f"cannot listen for RTDE: {exc.strerror or exc}") from None
        self.port = sock.getsockname()[1]
        self._listener = sock
        if thread:
            self.serve_in_thread()
        return self

    def serve_in_thread(self) -> None:
        """Serve in a daemon thread, once. On Linux a new thread takes its creator's
        scheduling policy and CPU set, so the caller's real-time settings carry over."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._serve, name="rtde-server",
                                            daemon=True)
            self._thread.start()

    def close(self) -> None:
        """Stop serving and close every connection."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        for conn in list(self._conns.values()):
            self._drop(conn, "server closed")
        if self._listener is not None:
            self._listener.close()
            self._listener = None

    def kill(self) -> None:
        """End at once, as a controller whose process died: serving stops and every
        connection is shut down under its client (who reads it closed); returns without
        waiting for the serving thread (:meth:`close` still releases everything)."""
        self._stop.set()
        for sock in list(self._conns):
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass

    def __enter__(self) -> RtdeServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def clients(self) -> int:
        """Connections open now."""
        return len(self._conns)

    # ------------------------------------------------------------------ the loop

    def _serve(self) -> None:
        try:
            while not self._stop.is_set():
                self._poll(self._wait_s())
                self._flush_delayed()
                if self._due():
                    self._step_once()
        except BaseException as exc:  # handed to the owner; the clients see the link drop
            self.error = exc
            for conn in list(self._conns.values()):
                self._drop(conn, f"server error: {exc}")

    def _streaming(self) -> list[_Connection]:
        return [c for c in self._conns.values() if c.streaming]

    def _wait_s(self) -> float:
        wait = self._wait_stream_s()
        held = [c.delayed[0][0] for c in self._conns.values() if c.delayed]
        return max(0.0, min(wait, min(held) - time.monotonic())) if held else wait

    def _wait_stream_s(self) -> float:
        if not self._streaming():
            return _IDLE_WAIT_S
        now = time.monotonic()
        if self.pacing == "realtime":
            return max(0.0, min(_IDLE_WAIT_S, self._next_due - now))
        if self._awaiting():
            return max(0.0, min(_IDLE_WAIT_S, self._wait_until - now))
        return 0.0

    def _awaiting(self) -> list[_Connection]:
        if not self.lockstep_wait_inputs:
            return []
        return [c for c in self._streaming() if c.inputs and not c.answered]

    def _due(self) -> bool:
        if not self._streaming():
            return False
        now = time.monotonic()
        if self.pacing == "realtime":
            if now < self._next_due:
                return False
            period = 1.0 / self.base_hz
            late = int((now - self._next_due) / period)
            if late:
                self.counters["late_steps"] += late
                self._step += late
            self._next_due += (late + 1) * period
            return True
        waiting = self._awaiting()
        if waiting and now < self._wait_until:
            return False
        if waiting:
            self.counters["lockstep_misses"] += 1
        return True

    def _step_once(self) -> None:
        values = self.source()
        self.counters["steps"] += 1
        k = self._step
        self._step += 1
        for conn in self._streaming():
            if conn.output is None or not self._sends_at(conn, k):
                continue
            record = self._fill(conn.output, values)
            data = codec.package(PackageType.DATA_PACKAGE,
                                 bytes((conn.output.recipe_id,)) + record)
            conn.answered = False
            self._send_data(conn, data, k)
        self._wait_until = time.monotonic() + self.lockstep_timeout_s

    def _send_data(self, conn: _Connection, data: bytes, k: int) -> None:
        f = self.faults
        if f.loss and self._rng.random() < f.loss:
            self.counters["faults_dropped"] += 1
            self.dropped_steps.append(k)
            conn.answered = True  # nothing to answer
            return
        if f.delay_s:
            conn.delayed.append((time.monotonic() + f.delay_s, data))
            self.counters["faults_delayed"] += 1
            return
        self._send_counted(conn, data)

    def _send_counted(self, conn: _Connection, data: bytes) -> None:
        if not self._send(conn, data):
            return
        self.counters["sent"] += 1
        conn.data_sent += 1
        if self.faults.disconnect_after and conn.data_sent >= self.faults.disconnect_after:
            self.counters["faults_disconnected"] += 1
            self._drop(conn, "fault injection: disconnect")

    def _flush_delayed(self) -> None:
        now = time.monotonic()
        for conn in list(self._conns.values()):
            while conn.delayed and conn.delayed[0][0] <= now and conn.sock in self._conns:
                self._send_counted(conn, conn.delayed.popleft()[1])

    def _sends_at(self, conn: _Connection, k: int) -> bool:
        n = k - conn.started_step
        ratio = conn.output_hz / self.base_hz
        return math.floor((n + 1) * ratio + 1e-9) > math.floor(n * ratio + 1e-9)

    def _fill(self, recipe: Recipe, values: Mapping[str, object]) -> bytes:
        record = recipe.empty()
        for name in recipe.names:
            if name in values:
                record[name] = values[name]
            elif name in self.inputs:
                record[name] = self.inputs[name]
            else:
                self.counters["missing_values"] += 1
        return record.tobytes()

    # ------------------------------------------------------------------ sockets

    def _poll(self, timeout_s: float) -> None:
        assert self._listener is not None
        socks = [self._listener, *self._conns]
        readable, _, _ = select.select(socks, [], [], timeout_s)
        for sock in readable:
            if sock is self._listener:
                self._accept()
            elif sock in self._conns:
                self._read(self._conns[sock])

    def _accept(self) -> None:
        assert self._listener is not None
        sock, peer = self._listener.accept()
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.settimeout(2.0)
        address = f"{peer[0]}:{peer[1]}"
        self._conns[sock] = _Connection(sock, address, codec.Framer(address))
        self.counters["connections"] += 1

    def _read(self, conn: _Connection) -> None:
        try:
            data = conn.sock.recv(65536)
        except OSError:
            data = b""
        if not data:
            self._drop(conn, "closed by the client")
            return
        conn.framer.feed(data)
        while conn.sock in self._conns:
            try:
                got = conn.framer.next()
            except MalformedPacketError as exc:
                self.counters["rejected"] += 1
                self._drop(conn, str(exc))
                return
            if got is None:
                return
            try:
                msg = codec.decode_from_client(got[0], got[1], conn.inputs, conn.address)
            except MalformedPacketError as exc:
                self.counters["rejected"] += 1
                self._say(conn, str(exc), codec.MessageLevel.ERROR)
                continue
            self.counters["received"] += 1
            self._handle(conn, msg)

    def _send(self, conn: _Connection, data: bytes) -> bool:
        try:
            conn.sock.sendall(data)
        except OSError as exc:
            self._drop(conn, f"send failed: {exc}")
            return False
        return True

    def _say(self, conn: _Connection, text: str, level: int) -> None:
        self._send(conn, codec.encode(codec.TextMessage(text[:255], "RTDE", level)))

    def _drop(self, conn: _Connection, why: str) -> None:
        if self._conns.pop(conn.sock, None) is not None:
            self.counters["dropped"] += 1
        conn.sock.close()

    # ------------------------------------------------------------------ requests

    def _handle(self, conn: _Connection, msg: codec.ClientMessage) -> None:
        reply: codec.ControllerMessage | None = None
        if isinstance(msg, codec.DataPackage):
            values = _values(conn.inputs[msg.recipe_id], msg.record)
            self.inputs.update(values)
            conn.written.update(values)
            conn.answered = True
            self.counters["inputs"] += 1
            if self.sink is not None:
                self.sink(values)
        elif isinstance(msg, codec.RequestProtocolVersion):
            reply = codec.Accepted(PackageType.REQUEST_PROTOCOL_VERSION,
                                   msg.version in self.protocol_versions)
        elif isinstance(msg, codec.GetControllerVersion):
            reply = self.controller_version
        elif isinstance(msg, codec.SetupOutputs):
            reply = self._setup_outputs(conn, msg)
        elif isinstance(msg, codec.SetupInputs):
            reply = self._setup_inputs(conn, msg)
        elif isinstance(msg, codec.Start):
            ok = conn.output is not None or bool(conn.inputs)
            if ok and not conn.streaming:
                self._begin(conn)
            if not ok:
                self._say(conn, "start without a recipe", codec.MessageLevel.ERROR)
            reply = codec.Accepted(PackageType.CONTROL_PACKAGE_START, ok)
        elif isinstance(msg, codec.Pause):
            conn.streaming = False
            reply = codec.Accepted(PackageType.CONTROL_PACKAGE_PAUSE, True)
        elif isinstance(msg, codec.TextMessage):
            self.messages.append(msg)
        if reply is not None:
            self._send(conn, codec.encode(reply))

    def _begin(self, conn: _Connection) -> None:
        if not self._streaming():
            self._next_due = time.monotonic()
            if not conn.started_once:  # a new client alone: a new session
                if self.on_session is not None:
                    self.on_session()
                    self.inputs = dict(conn.written)
                    if self.sink is not None and conn.written:
                        self.sink(conn.written)
                self.counters["sessions"] += 1
        conn.started_once = True
        conn.streaming = True
        conn.answered = True
        conn.started_step = self._step

    def _refuse(self, conn: _Connection, request: PackageType, types: tuple[str, ...],
                why: str) -> codec.RecipeReply:
        self._say(conn, why, codec.MessageLevel.ERROR)
        self.counters["refused_recipes"] += 1
        return codec.RecipeReply(request, 0, types)

    def _setup_outputs(self, conn: _Connection, msg: codec.SetupOutputs) -> codec.RecipeReply:
        request = PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS
        types = tuple(OUTPUTS[n] if n in self.outputs or n in INPUTS else NOT_FOUND
                      for n in msg.names)
        if conn.streaming:
            return self._refuse(conn, request, types, "setup while streaming: pause first")
        if not codec.frequency_ok(msg.frequency_hz, self.base_hz):
            return self._refuse(conn, request, types,
                                f"output frequency {msg.frequency_hz:g} Hz is outside "
                                f"(0, {self.base_hz:g}]")
        if NOT_FOUND in types or not msg.names or len(set(msg.names)) != len(msg.names):
            return self._refuse(conn, request, types, "output recipe has unknown or repeated "
                                "variables")
        if conn.next_id > 255:
            return self._refuse(conn, request, types, "more than 255 recipes on one connection")
        conn.output = Recipe(self._new_id(conn), msg.names, types)
        conn.output_hz = msg.frequency_hz
        return codec.RecipeReply(request, conn.output.recipe_id, types)

    def _setup_inputs(self, conn: _Connection, msg: codec.SetupInputs) -> codec.RecipeReply:
        request = PackageType.CONTROL_PACKAGE_SETUP_INPUTS
        others = set().union(*(c.held() for c in self._conns.values() if c is not conn))
        types = tuple(NOT_FOUND if n not in INPUTS else IN_USE if n in others else INPUTS[n]
                      for n in msg.names)
        if conn.streaming:
            return self._refuse(conn, request, types, "setup while streaming: pause first")
        if (NOT_FOUND in types or IN_USE in types or not msg.names
                or len(set(msg.names)) != len(msg.names)):
            return self._refuse(conn, request, types, "input recipe has unknown, held or "
                                "repeated variables")
        if conn.next_id > 255:
            return self._refuse(conn, request, types, "more than 255 recipes on one connection")
        recipe = Recipe(self._new_id(conn), msg.names, types)
        conn.inputs[recipe.recipe_id] = recipe
        return codec.RecipeReply(request, recipe.recipe_id, types)

    def _new_id(self, conn: _Connection) -> int:
        conn.next_id += 1
        return conn.next_id - 1


def _values(recipe: Recipe, record: np.ndarray) -> dict[str, Any]:
    """A data package's fields as plain values: Python scalars, native float64/int arrays."""
    out: dict[str, Any] = {}
    for name in recipe.names:
        v = record[name]
        out[name] = v.astype(v.dtype.newbyteorder("=")) if v.ndim else v.item()
    return out
