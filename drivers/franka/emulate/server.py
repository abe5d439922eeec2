"""The emulated FR3 over libfranka's network protocol: ``ffexp emulate --robot fr3``.

:class:`FciServer` listens on ``host:port`` (libfranka's command port 1337 by default; any
loopback address may be chosen, so that parallel tests each have their own) for one
client at a time and serves the world's FR3
(:class:`~drivers.franka.emulate.controller.Fr3SimController`) in a thread of its own:

* TCP: ``Connect`` (the client's version checked against the server's: a mismatch is
  answered ``kIncompatibleLibraryVersion`` with the server's version, as a robot does),
  ``GetRobotModel`` (the FR3's URDF, :mod:`drivers.franka.urdf`), ``Move`` (a torque loop
  with the external controller: ``kMotionStarted``, then how it ended: ``kSuccess``, or
  ``kReflexAborted`` after a reflex), ``StopMove``, the setters and error recovery
  (answered ``kSuccess``).
* UDP: every cycle a ``RobotState`` to the client's port (from this server's UDP socket,
  where the client's ``RobotCommand`` comes back).

Pacing: ``realtime``, one cycle per millisecond of the wall clock (a cycle that began more
than a cycle late is counted an ``overrun``: the robot's clock then lags the wall's, as
on a machine too loaded to serve 1 kHz; a command that came for
an older state is counted ``late`` and not applied, one that never came ``missed``: the
robot then keeps the last torque, and ``control_command_success_rate`` drops, as a robot
counts it); ``lockstep``, the world steps on each command for the current state, and
only then: while no motion runs the same state is sent again every millisecond with a new
id, the world not stepping, so that a client that reads without commanding sees time
pass; in a motion, until its first command, the motion's first state, and when no command
answers it within a cycle one newer state (libfranka takes the first while it starts the
motion and waits for a newer one before it commands; time passes, the world rests), is
sent again every millisecond with its own id, and a client's first command answers it
whenever it comes, so the run does not depend on how long the client took to start; once
commands come, each state waits for its own, and after ``lockstep_timeout_s`` without it
the cycle is missed and the world steps with the last torque (a stop or a closed
connection ends the wait at once). So the world's steps are the commands, one by one, as
in-process.

Faults (:class:`FciFaults`): ``silence`` (connections accepted, never answered),
``version`` (the server's protocol version), ``drop_after`` (the connection closed that
many milliseconds into a motion), ``reflex_after`` (a ``cartesian_reflex`` then).
"""

from __future__ import annotations

import select
import socket
import struct
import threading
import time
from collections import Counter
from dataclasses import dataclass
from typing import Literal

import numpy as np

from drivers.errors import AddressError
from drivers.franka import codec
from drivers.franka.emulate.controller import Fr3SimController
from drivers.franka.urdf import urdf
from drivers.net.udp import resolve_ipv4
from drivers.world.world import SimWorld

__all__ = ["FciFaults", "FciServer"]

_CYCLE_S = 0.001
#: The end of a real-time cycle's wait spent spinning (a sleep wakes up that late).
_SPIN_S = 0.0002
_POLL_S = 0.05
_MESSAGE_ID = struct.Struct("<Q")  # a command's first field
#: Cycles whose CPU cost is kept (the last ones; a preallocated ring).
COST_WINDOW = 1 << 16


@dataclass(frozen=True)
class FciFaults:
    """Faults the emulated FR3 injects (0: none)."""

    silence: bool = False
    version: int = codec.VERSION
    drop_after: int = 0
    reflex_after: int = 0


class FciServer:
    """The world's FR3 over libfranka's protocol on ``host:port`` (module docstring)."""

    def __init__(self, world: SimWorld, host: str, port: int, *,
                 pacing: Literal["realtime", "lockstep"] = "realtime",
                 lockstep_timeout_s: float = 1.0, faults: FciFaults | None = None,
                 where: str = "--listen") -> None:
        self.world = world
        self.controller = Fr3SimController(world)
        self.pacing = pacing
        self.lockstep_timeout_s = lockstep_timeout_s
        self.faults = faults or FciFaults()
        self.where = where
        self.counters: Counter[str] = Counter()
        self.error: BaseException | None = None
        ip = resolve_ipv4(where, host)
        self._tcp = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._tcp.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self._tcp.bind((ip, port))
        except OSError as exc:
            self._tcp.close()
            raise AddressError(where, f"{host}:{port}", exc.strerror or str(exc)) from None
        self._tcp.listen(1)
        self._udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._udp.bind((ip, 0))
        self._udp.setblocking(False)
        self._conn: socket.socket | None = None
        self._client: tuple[str, int] | None = None
        self._inbox = b""
        self._move_id: int | None = None
        self._motion_ms = 0
        self._commanded = False  # a command came in the running motion
        self._next = time.monotonic()  # real time: when the current cycle was due
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._cmd = bytearray(codec.ROBOT_COMMAND.itemsize + 64)
        # the received command, read in place (a view of the receive buffer)
        self._cmd_rec: np.void = np.frombuffer(self._cmd, dtype=codec.ROBOT_COMMAND,
                                               count=1)[0]
        self._tcp_pending = True  # the client's TCP connection may have bytes to read
        # what the cycle's select watches: the UDP socket, or it and the TCP connection
        self._watch_udp: list[int] = []
        self._watch_both: list[int] = []
        self._cost_ns = [0] * COST_WINDOW  # a plain list: one store a cycle
        self._costs = 0

    @property
    def address(self) -> tuple[str, int]:
        host, port = self._tcp.getsockname()[:2]
        return str(host), int(port)

    @property
    def steps(self) -> int:
        """World steps so far (milliseconds of simulated time)."""
        return self.controller.steps

    # ------------------------------------------------------------ lifecycle
    @property
    def started(self) -> bool:
        """The serving thread was started (:meth:`start`)."""
        return self._thread is not None

    def start(self) -> FciServer:
        self._thread = threading.Thread(target=self._run, name="fci-server", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(5.0)
        self._drop()
        self._tcp.close()
        self._udp.close()

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                if self._conn is None:
                    self._accept()
                else:
                    self._cycle()
        except BaseException as exc:  # re-raised by the caller (served.py)
            self.error = exc

    def _drop(self) -> None:
        conn, self._conn, self._client = self._conn, None, None
        self._inbox = b""
        if conn is not None:
            conn.close()
        self.controller.finish_motion(codec.MoveStatus.ABORTED)
        self.controller.ended = None
        self._move_id = None

    # ------------------------------------------------------------ TCP
    def _accept(self) -> None:
        ready, _, _ = select.select([self._tcp], [], [], _POLL_S)
        if not ready:
            return
        conn, peer = self._tcp.accept()
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.counters["connections"] += 1
        if self.faults.silence:
            self._silent(conn)
            return
        conn.settimeout(5.0)
        try:
            data = _recv_exact(conn, codec.CONNECT_REQUEST.itemsize)
        except OSError:
            conn.close()
            return
        req = codec.decode(codec.CONNECT_REQUEST, data)
        cid = int(req["header"]["command_id"])
        ok = int(req["version"]) == self.faults.version
        status = codec.ConnectStatus.SUCCESS if ok else \
            codec.ConnectStatus.INCOMPATIBLE_LIBRARY_VERSION
        conn.sendall(codec.message(codec.CONNECT_RESPONSE, codec.Command.CONNECT, cid,
                                   status=int(status), version=self.faults.version))
        if not ok:
            self.counters["refused_versions"] += 1
            conn.close()
            return
        conn.setblocking(False)
        self._conn, self._client = conn, (peer[0], int(req["udp_port"]))
        # the states go to the client's port only, and only its datagrams come back (a
        # connected socket: no address to pass or return every cycle)
        self._udp.connect(self._client)
        self._watch_udp = [self._udp.fileno()]
        self._watch_both = [self._udp.fileno(), conn.fileno()]
        self._tcp_pending = True

    def _silent(self, conn: socket.socket) -> None:
        """Hold the connection without a word until the client gives up or we stop."""
        while not self._stop.is_set():
            ready, _, _ = select.select([conn], [], [], _POLL_S)
            if ready:
                try:
                    if not conn.recv(4096):
                        break
                except OSError:
                    break
        conn.close()

    def _read_tcp(self) -> None:
        assert self._conn is not None
        self._tcp_pending = False
        try:
            data = self._conn.recv(65536)
        except BlockingIOError:
            return
        except OSError:
            data = b""
        if not data:  # the client closed the connection
            self.counters["disconnects"] += 1
            self._drop()
            return
        self._inbox += data
        while len(self._inbox) >= codec.HEADER.itemsize:
            head = codec.header_of(self._inbox)
            size = int(head["size"])
            if len(self._inbox) < size:
                return
            msg, self._inbox = self._inbox[:size], self._inbox[size:]
            self._command(int(head["command"]), int(head["command_id"]), msg)
            if self._conn is None:
                return

    def _reply(self, command: int, command_id: int, status: int, body: bytes = b"") -> None:
        assert self._conn is not None
        head = np.zeros((), dtype=codec.HEADER)
        head["command"], head["command_id"] = command, command_id
        head["size"] = codec.HEADER.itemsize + 1 + len(body)
        self._conn.setblocking(True)
        try:
            self._conn.sendall(head.tobytes() + bytes([status]) + body)
        finally:
            self._conn.setblocking(False)

    def _command(self, command: int, command_id: int, msg: bytes) -> None:
        c = self.controller
        self.counters[f"tcp_{codec.Command(command).name.lower()}"
                      if command in codec.Command._value2member_map_ else "tcp_unknown"] += 1
        if command == codec.Command.MOVE:
            req = codec.decode(codec.MOVE_REQUEST, msg[:codec.MOVE_REQUEST.itemsize])
            status = c.start_motion(
                codec.MoveMotionGeneratorMode(int(req["motion_generator_mode"])),
                codec.MoveControllerMode(int(req["controller_mode"])))
            self._reply(command, command_id, int(status))
            if status == codec.MoveStatus.MOTION_STARTED:
                self._move_id, self._motion_ms, self._commanded = command_id, 0, False
        elif command == codec.Command.STOP_MOVE:
            c.finish_motion(codec.MoveStatus.PREEMPTED)
            self._reply(command, command_id, 0)
        elif command == codec.Command.GET_ROBOT_MODEL:
            self._reply(command, command_id, 0, urdf().encode())
        elif command == codec.Command.AUTOMATIC_ERROR_RECOVERY:
            c.recover()
            self._reply(command, command_id, 0)
        elif command in codec.Command._value2member_map_:
            self._reply(command, command_id, 0)  # the setters: accepted
        else:
            self._reply(command, command_id, 1)  # rejected

    # ------------------------------------------------------------ UDP
    def _send_state(self) -> None:
        try:
            self._udp.send(self.controller.state().data)  # the record's own bytes
        except OSError:  # the client's port closed (its ICMP answer): the TCP link tells
            self.counters["udp_errors"] += 1
        self.counters["states"] += 1

    def _take_commands(self, timeout_s: float) -> np.void | None:
        """The command for the current state, waiting up to ``timeout_s``; older ones are
        counted late. The record returned is a view of the receive buffer, valid until
        the next call. The client's TCP connection is watched too: bytes there are read
        at the next cycle's start (not every cycle looks), except in lockstep, where they
        are read at once: a stop or a closed connection ends the wait (the client sends no
        more commands), anything else leaves it waiting."""
        end = time.monotonic() + timeout_s
        want = self.controller.message_id
        udp = self._udp
        while True:
            watch = self._watch_udp if self._tcp_pending or self._conn is None else \
                self._watch_both
            ready, _, _ = select.select(watch, [], [], max(0.0, end - time.monotonic()))
            if len(ready) > 1 or (ready and ready[0] is not watch[0]):  # the TCP link's bytes
                self._tcp_pending = True
            if ready and ready[0] is watch[0]:  # a command first, if one came with them
                while True:
                    try:
                        n = udp.recv_into(self._cmd)
                    except (BlockingIOError, InterruptedError):
                        break
                    except OSError:  # the client's port closed (its ICMP answer)
                        self.counters["udp_errors"] += 1
                        break
                    if n != codec.ROBOT_COMMAND.itemsize:
                        self.counters["malformed"] += 1
                        continue
                    if _MESSAGE_ID.unpack_from(self._cmd)[0] == want:
                        return self._cmd_rec
                    self.counters["late"] += 1
            if self._tcp_pending and self.pacing == "lockstep" and self._conn is not None:
                self._read_tcp()  # a stop or a closed link ends the wait
                if self._conn is None or not self.controller.moving:
                    return None
            if not ready or time.monotonic() >= end:
                return None

    def cycle_cpu_us(self) -> dict[str, float]:
        """The serving thread's CPU time per cycle with a client (the last
        :data:`COST_WINDOW` cycles; waits for the command and the pacing's sleep left
        out) [us]: p50, p99, max; empty before the first cycle."""
        costs = np.array(self._cost_ns[:min(self._costs, COST_WINDOW)]) / 1e3
        if not costs.size:
            return {}
        p50, p99 = np.percentile(costs, (50, 99))
        return {"p50": round(float(p50), 1), "p99": round(float(p99), 1),
                "max": round(float(costs.max()), 1)}

    def _cost(self, cpu0_ns: int) -> None:
        self._cost_ns[self._costs % COST_WINDOW] = time.thread_time_ns() - cpu0_ns
        self._costs += 1

    def _cycle(self) -> None:
        """One cycle with a client: its TCP commands, a state, its answer, a step."""
        c = self.controller
        cpu0 = time.thread_time_ns()
        if self._tcp_pending or self.pacing == "lockstep":
            self._read_tcp()
        if self._conn is None:
            return
        t0 = due = time.monotonic()
        if self.pacing == "realtime":  # cycles due on the wall clock's millisecond grid
            due = self._next
            if t0 > due + _CYCLE_S:  # began more than a cycle late: the clock lags
                self.counters["overruns"] += 1
                due = t0  # and the grid starts again from now
            self._next = due + _CYCLE_S
        self._send_state()
        if self.pacing == "lockstep":
            cmd = None
            if c.moving and self._commanded:
                cmd = self._take_commands(self.lockstep_timeout_s)
            elif c.moving:  # its first command: the state sent again until it comes
                end = time.monotonic() + self.lockstep_timeout_s
                cmd = self._take_commands(_CYCLE_S)
                if cmd is None and c.moving:
                    # libfranka takes the motion's first state while it starts the motion
                    # and then waits for a newer one: one more, time passing, the world
                    # resting (as a reader's time passes outside a motion)
                    c.message_id += 1
                    self._send_state()
                    cmd = self._take_commands(_CYCLE_S)
                while cmd is None and c.moving and time.monotonic() < end:
                    self._send_state()
                    cmd = self._take_commands(_CYCLE_S)
                self._commanded = cmd is not None
            if cmd is None and not (c.moving and self._commanded):
                c.message_id += 1  # time passes for the reader, the world rests
                self._cost(cpu0)
                _sleep_until(t0 + _CYCLE_S)
                return
        elif c.moving:
            cmd = self._take_commands(max(0.0, due + _CYCLE_S * 0.9 - time.monotonic()))
        else:  # no motion: no command to wait for (one that comes is seen in the pause)
            cmd = None
        if c.moving:
            self.counters["answered" if cmd is not None else "missed"] += 1
        c.step(cmd)
        self._motion_events()
        self._cost(cpu0)
        if self.pacing == "realtime":
            self._pause_until(self._next)  # a short cycle makes up for a long one

    def _pause_until(self, deadline: float) -> None:
        """Real time: wait for ``deadline`` (monotonic; its last :data:`_SPIN_S` spinning),
        watching the client's TCP connection (bytes there are read at the next cycle's
        start) and, while no motion runs, its UDP socket (a command then answers no state:
        counted late)."""
        watch = [] if self._tcp_pending or self._conn is None else self._watch_both[1:]
        if not self.controller.moving:
            watch = watch + self._watch_udp
        while (left := deadline - _SPIN_S - time.monotonic()) > 0.0:
            if not watch:
                time.sleep(left)
                break
            ready, _, _ = select.select(watch, [], [], left)
            if not ready:
                break
            for fd in ready:
                watch.remove(fd)
                if fd in self._watch_udp:
                    self._drain_late()
                else:
                    self._tcp_pending = True
        _sleep_until(deadline)

    def _drain_late(self) -> None:
        """Every command waiting on the UDP socket, counted late (no state awaits it)."""
        while True:
            try:
                n = self._udp.recv_into(self._cmd)
            except OSError:  # none left (or the client's port closed)
                return
            self.counters["late" if n == codec.ROBOT_COMMAND.itemsize else "malformed"] += 1

    def _motion_events(self) -> None:
        c = self.controller
        if c.moving:
            self._motion_ms += 1
            f = self.faults
            if f.reflex_after and self._motion_ms == f.reflex_after:
                c.inject_reflex()
                self.counters["faults_reflex"] += 1
            if f.drop_after and self._motion_ms == f.drop_after:
                self.counters["faults_dropped"] += 1
                self._drop()
                return
        if c.ended is not None and self._move_id is not None and self._conn is not None:
            self._reply(codec.Command.MOVE, self._move_id, int(c.ended))
            c.ended, self._move_id = None, None

    def summary(self, cost: bool = True) -> str:
        """The counters in one line, and (``cost``) the cycles' CPU cost."""
        cost_us = self.cycle_cpu_us() if cost else {}
        return " ".join([*(f"{k} {v}" for k, v in sorted(self.counters.items())),
                         *(f"cycle_cpu_us_{k} {v:g}" for k, v in cost_us.items())])


def _recv_exact(conn: socket.socket, n: int) -> bytes:
    data = b""
    while len(data) < n:
        chunk = conn.recv(n - len(data))
        if not chunk:
            raise ConnectionError("closed")
        data += chunk
    return data


def _sleep_until(deadline: float, spin_s: float = _SPIN_S) -> None:
    """Sleep until ``deadline`` (monotonic): the last ``spin_s`` spinning."""
    left = deadline - time.monotonic()
    if left > spin_s:
        time.sleep(left - spin_s)
    while time.monotonic() < deadline:
        pass

