"""The FRI 1.x remote driver: the researcher's PC side of the KRC link, over UDP.

The KRC is the clock. After ``friOpen`` it sends one 916-byte measurement
per cycle to ``FRIHOST:FRISOCK`` (this driver's address and port) and expects
one 376-byte command back within the cycle. :class:`FriRobot` therefore runs
a dedicated I/O thread that

* accepts datagrams only from the configured robot address (others are
  counted as foreign), validates them with the codec (rejections counted per
  reason) and tracks the sequence counter: gaps (lost measurements),
  duplicates (answered again with the same reply, not passed on) and
  reordered/stale packets (dropped);
* hands the measurement to the runner (``measurements()``) and answers it:
  **as soon as the runner has sent its command for this cycle**, or at the
  latest ``answer_deadline`` cycles after the packet arrived (default half a
  cycle). A runner that is late therefore never stalls the KRC link: at the
  deadline the I/O thread repeats the last command the runner sent (counted
  in :attr:`LinkStats.deadline_answers`); the late command is not sent for
  the past cycle but becomes the latest command for the next one. With
  ``answer_deadline = 0`` every measurement is answered on arrival with the
  latest command (the Stanford FRI library's scheme: one cycle more delay,
  always prompt). A lockstep emulator marks its packets (see
  :mod:`drivers.fri.convert`); the driver then waits for the runner's command
  of each cycle (up to ``runner_timeout_s``), so lockstep runs do not depend
  on thread timing;
* mirrors the KRC while it is not commanding (state not CMD or drives off):
  ``jntPos = cmdJntPos + cmdJntPosFriOffset`` and ``cartPos = cmdCartPos``
  replace the runner's targets, so entering command mode cannot jump;
* stamps each measurement with the KRC's cycle time: unwrapped
  ``sendSeqCount`` times ``desiredMsrSampleTime`` (the float32
  ``intf.timestamp`` is too coarse for nanoseconds), so lost cycles still
  advance time. Ground truth does not travel over FRI: ``truth`` is ``None``.

If the runner falls behind by whole cycles it gets the newest measurement;
the ones it never saw are counted (:attr:`LinkStats.skipped`).
:attr:`FriRobot.stats` is a snapshot of every counter and of the KRC's own
link statistics (answer rate, latency, jitter, miss counter, quality, state).
"""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import NDArray

from drivers.base.interfaces import ForceTorqueSensor, RobotDriver
from drivers.base.types import Command, FriQuality, FriState, FtSamples, Measurement
from drivers.errors import (
    DriverError,
    DriverTimeoutError,
    LinkLostError,
    NotConnectedError,
)
from drivers.fri.codec import (
    DEFAULT_PORT,
    CmdArrays,
    DecodeStats,
    DecodeStatus,
    MsrArrays,
    SeqEvent,
    classify_seq,
    decode_msr_into,
    encode_cmd,
    new_cmd_buffer,
    seq_next,
)
from drivers.fri.convert import (
    LOCKSTEP_INDEX,
    LOCKSTEP_MARKER,
    arrays_to_measurement,
    command_to_arrays,
    cycle_ns_from_seconds,
)
from drivers.net.udp import bind_udp, resolve_ipv4

__all__ = ["FriEstimateSensor", "FriRobot", "FriSettings", "LinkStats"]

#: Plausible ``desiredMsrSampleTime`` [s]: friOpen takes 1..100 ms.
MIN_CYCLE_S: Final = 0.0009
MAX_CYCLE_S: Final = 0.101
#: A measurement older than this many cycles is taken as a KRC restart, not as reordering.
RESTART_SEQ_JUMP: Final = 100
_TURNAROUND_CAPACITY: Final = 1 << 17


@dataclass(frozen=True)
class FriSettings:
    """Where the KRC is and how to answer it.

    Args:
        robot_ip: the KRC's address; packets from anywhere else are dropped.
        port: local UDP port (``FRISOCK`` in the KRC's dlrrc.ini; 0 = any free port).
        bind_host: local address to bind (default all interfaces).
        robot_port: if set, also require this source port.
        answer_deadline: latest answer, in cycles after the packet arrived;
            0 answers on arrival with the latest command.
        follow_lockstep_marker: wait for the runner when the emulator says lockstep.
        connect_timeout_s: longest wait for the first measurement.
        cycle_timeout_s: longest gap between measurements before the link is lost.
        runner_timeout_s: in lockstep, longest wait for the runner's command.
    """

    robot_ip: str
    port: int = DEFAULT_PORT
    bind_host: str = "0.0.0.0"
    robot_port: int | None = None
    answer_deadline: float = 0.5
    follow_lockstep_marker: bool = True
    connect_timeout_s: float = 10.0
    cycle_timeout_s: float = 1.0
    runner_timeout_s: float = 5.0


@dataclass(frozen=True)
class LinkStats:
    """A snapshot of the link, for logs (driver counters and the KRC's own view)."""

    received: int
    """Datagrams received on the port (any source)."""
    foreign: int
    """Datagrams from an address other than the robot's, dropped."""
    decode: dict[str, int]
    """Codec outcome counts of the robot's datagrams (ok, too_short, wrong_id, ...)."""
    accepted: int
    """Measurements accepted (new sequence numbers)."""
    duplicates: int
    stale: int
    """Reordered (older) measurements, dropped."""
    lost: int
    """Measurements missing in the sequence (gaps)."""
    restarts: int
    implausible: int
    """Measurements with a header but impossible contents (sample time, NaN), dropped."""
    answers: int
    """Command datagrams sent (including re-answers of duplicates)."""
    runner_answers: int
    """Cycles answered with the runner's command for that very cycle."""
    deadline_answers: int
    """Cycles answered at the deadline with the previous command (runner late)."""
    runner_late: int
    """Runner commands that came after their cycle had been answered."""
    skipped: int
    """Measurements the runner never saw (it fell behind by a cycle or more)."""
    turnaround_last_s: float
    """Packet received -> answer sent, last cycle."""
    turnaround_max_s: float
    state: FriState
    quality: FriQuality
    answer_rate: float
    latency_s: float
    jitter_s: float
    miss_rate: float
    miss_counter: int
    fallbacks: int
    """Times the KRC left command mode."""
    link_lost: bool
    """The KRC left command mode (or quality is UNACCEPTABLE) after having commanded."""


class FriRobot(RobotDriver):
    """The remote side of FRI 1.x over UDP (see the module docstring).

    Args:
        settings: addresses and answer policy.
    """

    def __init__(self, settings: FriSettings) -> None:
        self.settings = settings
        self.robot_ip = resolve_ipv4(settings.where("robot_ip"), settings.robot_ip)
        self._sock: socket.socket | None = None
        self._thread: threading.Thread | None = None
        self._cond = threading.Condition()
        self._stop = False
        self._connected = False
        self._error: DriverError | None = None
        self._listeners: list[Callable[[Measurement], None]] = []
        # cycle hand-over (guarded by _cond)
        self._pending: Measurement | None = None
        self._cycle = 0
        self._runner_cycle = -1
        self._answered = True
        self._reply_addr: tuple[str, int] | None = None
        self._reply_refl = 0
        self._mirror = True
        self._mirror_jnt = np.zeros(7)
        self._mirror_cart = np.eye(4)
        self._have_user = False
        self._lockstep = False
        self._t_rx = 0
        self._last_rx_ns = 0
        self._last_time_ns = 0
        self._last_cycle_ns = 5_000_000
        # commands
        self._user = CmdArrays()
        self._staged = CmdArrays()
        self._wire = CmdArrays()
        self._pb = new_cmd_buffer()
        self._check_pb = new_cmd_buffer()
        self._send_seq = 0
        self._last_reply: bytes | None = None
        # counters
        self.decode_stats = DecodeStats()
        self._received = 0
        self._foreign = 0
        self._accepted = 0
        self._duplicates = 0
        self._stale = 0
        self._lost = 0
        self._restarts = 0
        self._implausible = 0
        self._answers = 0
        self._runner_answers = 0
        self._deadline_answers = 0
        self._runner_late = 0
        self._skipped = 0
        self._fallbacks = 0
        self._was_cmd = False
        self._turn = np.zeros(_TURNAROUND_CAPACITY, dtype=np.int64)
        self._turn_n = 0
        self._turn_max = 0
        self._last_state = FriState.OFF
        self._last_quality = FriQuality.INVALID
        self._krc_stats = (0.0, 0.0, 0.0, 0.0, 0)
        # sequence
        self._last_seq: int | None = None
        self._unwrapped = 0
        self._time_base_ns = 0
        self._time_base_seq = 0

    # ------------------------------------------------------------ lifecycle
    def bind(self) -> tuple[str, int]:
        """Bind the UDP port now (``connect`` does it otherwise); returns the local address.

        Raises:
            AddressError: the port is in use or the address is not local.
        """
        if self._sock is None:
            s = self.settings
            self._sock = bind_udp(s.where("local_port"), s.local_host, s.local_port)
            self._sock.settimeout(0.05)
        host, port = self._sock.getsockname()[:2]
        return str(host), int(port)

    @property
    def local_address(self) -> tuple[str, int]:
        """The bound address (binds if needed)."""
        return self.bind()

    def connect(self) -> None:
        if self._connected:
            return
        self.bind()
        self._stop = False
        self._error = None
        self._connected = True
        self._thread = threading.Thread(target=self._io_loop, name="fri-io", daemon=True)
        self._thread.start()

    def close(self) -> None:
        with self._cond:
            self._stop = True
            self._connected = False
            self._cond.notify_all()
        t = self._thread
        if t is not None and t is not threading.current_thread():
            t.join(timeout=2.0)
        self._thread = None
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    @property
    def connected(self) -> bool:
        return self._connected

    def add_listener(self, callback: Callable[[Measurement], None]) -> None:
        """Call ``callback(m)`` from the I/O thread for every accepted measurement."""
        self._listeners.append(callback)

    # ------------------------------------------------------------ runner side
    def measurements(self) -> Iterator[Measurement]:
        if not self._connected:
            raise NotConnectedError(f"FRI robot {self.robot_ip}: measurements() before connect()")
        s = self.settings
        while True:
            with self._cond:
                first = self._accepted == 0
                limit = s.connect_timeout_s if first else s.cycle_timeout_s
                end = time.monotonic() + limit
                while self._pending is None and not self._stop and self._error is None:
                    remaining = end - time.monotonic()
                    if remaining <= 0.0:
                        break
                    self._cond.wait(remaining)
                if self._error is not None:
                    raise self._error
                if self._stop:
                    return
                m = self._pending
                if m is None:
                    raise self._timeout_error(first, limit)
                self._pending = None
                self._runner_cycle = self._cycle
            yield m

    def _timeout_error(self, first: bool, limit: float) -> DriverError:
        port = self._sock.getsockname()[1] if self._sock is not None else self.settings.port
        if first:
            return DriverTimeoutError(
                f"no FRI packet from {self.robot_ip} on UDP port {port} within {limit:g} s "
                "(check FRIHOST/FRISOCK in the KRC's dlrrc.ini, friOpen and the firewall)"
            )
        return LinkLostError(
            f"FRI link to {self.robot_ip} lost: no packet on UDP port {port} for {limit:g} s"
        )

    def send(self, command: Command) -> None:
        if not self._connected:
            raise NotConnectedError(f"FRI robot {self.robot_ip}: send() before connect()")
        staged = self._staged
        command_to_arrays(command, staged)
        encode_cmd(staged, self._check_pb)  # PacketEncodeError: never put NaN on the wire
        with self._cond:
            user = self._user
            user.floats[:] = staged.floats
            user.krl_int[:] = staged.krl_int
            user.krl_bool = staged.krl_bool
            user.cmd_flags = staged.cmd_flags
            self._have_user = True
            if self._runner_cycle == self._cycle and not self._answered:
                self._answer_locked()
                self._runner_answers += 1
                self._cond.notify_all()
            elif self.settings.answer_deadline > 0.0 or self._lockstep:
                self._runner_late += 1

    # ------------------------------------------------------------ clock & stats
    def now_ns(self) -> int | None:
        """The KRC's time now, estimated from the last measurement (``None`` before one).

        The wall time since that packet is added, at most one cycle (so that
        the estimate stays sane in lockstep, where wall time means nothing).
        """
        with self._cond:
            if self._accepted == 0:
                return None
            since = time.perf_counter_ns() - self._last_rx_ns
            return self._last_time_ns + min(max(since, 0), self._last_cycle_ns)

    def turnarounds_ns(self) -> NDArray[np.int64]:
        """Receive -> answer times of the answered cycles so far (up to the last 131072)."""
        with self._cond:
            n = self._turn_n
            if n <= _TURNAROUND_CAPACITY:
                return self._turn[:n].copy()
            k = n % _TURNAROUND_CAPACITY
            return np.concatenate([self._turn[k:], self._turn[:k]])

    @property
    def stats(self) -> LinkStats:
        with self._cond:
            ar, lat, jit, mr, mc = self._krc_stats
            last = self._turn[(self._turn_n - 1) % _TURNAROUND_CAPACITY] if self._turn_n else 0
            lost = self._was_cmd and (
                self._last_state != FriState.CMD or self._last_quality == FriQuality.UNACCEPTABLE
            )
            return LinkStats(
                received=self._received,
                foreign=self._foreign,
                decode=self.decode_stats.as_dict(),
                accepted=self._accepted,
                duplicates=self._duplicates,
                stale=self._stale,
                lost=self._lost,
                restarts=self._restarts,
                implausible=self._implausible,
                answers=self._answers,
                runner_answers=self._runner_answers,
                deadline_answers=self._deadline_answers,
                runner_late=self._runner_late,
                skipped=self._skipped,
                turnaround_last_s=int(last) * 1e-9,
                turnaround_max_s=self._turn_max * 1e-9,
                state=self._last_state,
                quality=self._last_quality,
                answer_rate=ar,
                latency_s=lat,
                jitter_s=jit,
                miss_rate=mr,
                miss_counter=mc,
                fallbacks=self._fallbacks,
                link_lost=lost,
            )

    # ------------------------------------------------------------ I/O thread
    def _io_loop(self) -> None:
        # a signalling NaN in a hostile packet would warn on every decode
        with np.errstate(invalid="ignore"):
            self._io_loop_inner()

    def _io_loop_inner(self) -> None:
        sock = self._sock
        assert sock is not None
        buf = bytearray(2048)
        view = memoryview(buf)
        msr = MsrArrays()
        robot_ip, robot_port = self.robot_ip, self.settings.robot_port
        clock = time.perf_counter_ns
        while not self._stop:
            try:
                n, addr = sock.recvfrom_into(buf)
            except TimeoutError:
                continue
            except OSError as exc:
                if not self._stop:
                    with self._cond:
                        self._error = LinkLostError(f"FRI socket failed: {exc}")
                        self._cond.notify_all()
                return
            t_rx = clock()
            self._received += 1
            if addr[0] != robot_ip or (robot_port is not None and addr[1] != robot_port):
                self._foreign += 1
                continue
            if decode_msr_into(view[:n], msr, stats=self.decode_stats) is not DecodeStatus.OK:
                continue
            try:
                self._on_measurement(msr, addr, t_rx)
            except OSError as exc:  # sendto failed (network down)
                with self._cond:
                    self._error = LinkLostError(f"FRI answer to {addr[0]}:{addr[1]} failed: {exc}")
                    self._cond.notify_all()
                return

    def _on_measurement(self, msr: MsrArrays, addr: tuple[str, int], t_rx: int) -> None:
        seq = msr.send_seq
        first = self._last_seq is None
        delta = 1
        event = SeqEvent.NEXT
        if self._last_seq is not None:
            event, delta = classify_seq(seq, self._last_seq)
            if event is SeqEvent.DUPLICATE:
                self._duplicates += 1
                if self._last_reply is not None and self._sock is not None:
                    self._sock.sendto(self._last_reply, addr)
                    self._answers += 1
                return
            if event is SeqEvent.STALE:
                if -delta <= RESTART_SEQ_JUMP:
                    self._stale += 1
                    return
                self._restarts += 1
                delta = 1
        sample_time = msr.msr_sample_time
        if not (
            MIN_CYCLE_S <= sample_time <= MAX_CYCLE_S
            and np.isfinite(msr.cmd_jnt_pos).all()
            and np.isfinite(msr.cmd_jnt_pos_fri_offset).all()
            and np.isfinite(msr.cmd_cart_pos).all()
        ):
            # a KRC never sends this; the packet cannot be mirrored or timed
            self._implausible += 1
            return
        self._last_seq = seq
        if first:
            self._unwrapped = seq
            self._time_base_seq = seq
        else:
            if event is SeqEvent.GAP:
                self._lost += delta - 1
            self._unwrapped += delta
        cycle_ns = cycle_ns_from_seconds(sample_time)
        if cycle_ns != self._last_cycle_ns:
            self._time_base_ns = self._time_ns(self._last_cycle_ns)
            self._time_base_seq = self._unwrapped
            self._last_cycle_ns = cycle_ns
        time_ns = self._time_ns(cycle_ns)
        m = arrays_to_measurement(msr, self._unwrapped, time_ns)
        for listener in self._listeners:
            listener(m)
        lockstep = self._lockstep = (
            self.settings.follow_lockstep_marker
            and int(msr.krl_int[LOCKSTEP_INDEX]) == LOCKSTEP_MARKER
        )
        state = m.state
        with self._cond:
            self._accepted += 1
            self._last_rx_ns = t_rx
            self._last_time_ns = time_ns
            if state == FriState.CMD:
                self._was_cmd = True
            elif self._last_state == FriState.CMD:
                self._fallbacks += 1
            self._last_state = state
            self._last_quality = m.quality
            self._krc_stats = (m.answer_rate, m.latency, m.jitter, m.miss_rate, m.miss_counter)
            if self._pending is not None:
                self._skipped += 1
            self._pending = m
            self._cycle += 1
            self._answered = False
            self._reply_addr = addr
            self._reply_refl = seq
            self._t_rx = t_rx
            self._mirror = state != FriState.CMD or m.power == 0
            self._mirror_jnt[:] = m.cmd_jnt_pos + m.cmd_jnt_pos_fri_offset
            self._mirror_cart[:] = m.cmd_cart_pos
            if not self._have_user:
                command_to_arrays(Command.hold(m), self._user)
            self._cond.notify_all()
            deadline = self.settings.answer_deadline
            if lockstep:
                wait_s = self.settings.runner_timeout_s
            else:
                wait_s = deadline * cycle_ns * 1e-9
            if wait_s > 0.0:
                end = time.monotonic() + wait_s
                while not self._answered and not self._stop:
                    remaining = end - time.monotonic()
                    if remaining <= 0.0:
                        break
                    self._cond.wait(remaining)
            if not self._answered and not self._stop:
                self._answer_locked()
                if wait_s > 0.0:
                    self._deadline_answers += 1

    def _time_ns(self, cycle_ns: int) -> int:
        return self._time_base_ns + (self._unwrapped - self._time_base_seq) * cycle_ns

    def _answer_locked(self) -> None:
        """Send the answer of the current cycle (caller holds ``_cond``)."""
        sock, addr = self._sock, self._reply_addr
        if sock is None or addr is None:
            return
        wire, user = self._wire, self._user
        wire.floats[:] = user.floats
        wire.krl_int[:] = user.krl_int
        wire.krl_bool = user.krl_bool
        wire.cmd_flags = user.cmd_flags
        if self._mirror:
            wire.jnt_pos[:] = self._mirror_jnt
            wire.cart_pos[:] = self._mirror_cart
        wire.send_seq = self._send_seq
        wire.refl_seq = self._reply_refl
        data = encode_cmd(wire, self._pb)
        sock.sendto(data, addr)
        turn = time.perf_counter_ns() - self._t_rx
        self._turn[self._turn_n % _TURNAROUND_CAPACITY] = turn
        self._turn_n += 1
        self._turn_max = max(self._turn_max, turn)
        self._send_seq = seq_next(self._send_seq)
        self._last_reply = data
        self._answers += 1
        self._answered = True


class FriEstimateSensor(ForceTorqueSensor):
    """The KRC's ``estExtTcpFT`` (from joint torques) read like an F/T sensor.

    One sample per FRI cycle, stamped with the cycle's time; the wrench is
    already in our convention (environment on the tool, TCF at the TCP).
    ``tare`` subtracts the last sample from then on (like Net F/T 0x0042).
    """

    def __init__(self, robot: FriRobot) -> None:
        self.robot = robot
        self._lock = threading.Lock()
        self._time: list[int] = []
        self._seq: list[int] = []
        self._wrench: list[NDArray[np.float64]] = []
        self._running = False
        self._bias = np.zeros(6)
        self._last: NDArray[np.float64] | None = None
        robot.add_listener(self._on_measurement)

    def _on_measurement(self, m: Measurement) -> None:
        if not self._running:
            return
        with self._lock:
            self._time.append(m.time_ns)
            self._seq.append(m.seq)
            self._wrench.append(m.est_ext_tcp_ft)

    def start(self) -> None:
        with self._lock:
            self._time.clear()
            self._seq.clear()
            self._wrench.clear()
        self._running = True

    def stop(self) -> None:
        self._running = False

    @property
    def running(self) -> bool:
        return self._running

    def samples(self) -> FtSamples:
        if not self._running:
            raise NotConnectedError("fri-estimate F/T: samples() before start()")
        with self._lock:
            t, s, w = self._time, self._seq, self._wrench
            self._time, self._seq, self._wrench = [], [], []
        if not t:
            return FtSamples()
        wrench = np.array(w, dtype=np.float64).reshape(-1, 6) - self._bias
        self._last = wrench[-1] + self._bias
        return FtSamples(
            time_ns=np.array(t, dtype=np.int64),
            seq=np.array(s, dtype=np.int64),
            wrench=wrench,
            status=np.zeros(len(t), dtype=np.uint32),
        )

    def tare(self) -> None:
        if not self._running:
            raise NotConnectedError("fri-estimate F/T: tare() before start()")
        if self._last is not None:
            self._bias = self._last.copy()

