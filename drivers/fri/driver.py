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
* hands the measurement to the runner (``measurements()``, as a
  :class:`~drivers.base.types.RobotState` whose ``extras`` is the
  :class:`~drivers.fri.types.FriMeasurement`) and answers it: **as soon as
  the runner has sent its command for this cycle**, or at the latest
  ``answer_deadline_cycles`` after the packet arrived (default half a cycle).
  A runner that is late therefore never stalls the KRC link: at the deadline
  the I/O thread answers with the last command the runner sent (counted in
  :attr:`LinkStats.deadline_answers`); the late command is not sent for the
  past cycle but becomes the latest command for the next one, and
  ``send()`` says so (:attr:`~drivers.base.types.ApplyStatus.LATE`). With
  ``answer_deadline_cycles = 0`` every measurement is answered on arrival
  with the latest command (the Stanford FRI library's scheme: one cycle more
  delay, always prompt; not flagged LATE). A lockstep emulator marks its
  packets (see :mod:`drivers.fri.convert`); the driver then waits for the
  runner's command of each cycle (up to ``runner_timeout_s``), so lockstep
  runs do not depend on thread timing;
* turns every answer into the FRI command with
  :func:`~drivers.fri.command.to_fri_command` against the cycle's own
  measurement: while the KRC is not commanding (state not CMD or drives off)
  it mirrors ``jntPos = cmdJntPos + cmdJntPosFriOffset`` and ``cartPos =
  cmdCartPos``, so entering command mode cannot jump;
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

import numpy as np
from numpy.typing import NDArray

from drivers.base.guards import requires_open
from drivers.base.interfaces import RobotDriver
from drivers.base.types import AppliedCommand, ApplyStatus, CartesianCommand, RobotState
from drivers.errors import DriverError, DriverTimeoutError, LinkLostError
from drivers.fri.codec import (
    CmdArrays,
    DecodeStats,
    DecodeStatus,
    MsrArrays,
    SeqEvent,
    classify_seq,
    decode_msr_into,
    new_cmd_buffer,
    pack_cmd,
    seq_next,
)
from drivers.fri.command import (
    applied_from_fri,
    copy_fri_command,
    robot_state_from_fri,
    to_fri_command,
)
from drivers.fri.config import FriRobotConfig
from drivers.fri.convert import (
    LOCKSTEP_INDEX,
    LOCKSTEP_MARKER,
    command_to_arrays,
    copy_measurement,
    cycle_ns_from_seconds,
    fill_measurement,
)
from drivers.fri.estimate import FriEstimateSensor
from drivers.fri.link import describe_error
from drivers.fri.stats import LinkCounters, LinkStats, LinkWatch
from drivers.fri.types import FriCommand, FriMeasurement, FriState, RemoteMeasurement
from drivers.net.udp import bind_udp, resolve_ipv4

__all__ = ["FriEstimateSensor", "FriRobot", "FriRobotConfig", "LinkStats"]

_WHAT = "FRI robot"

#: Sequence numbers remembered behind the newest one, to tell a late arrival
#: (it fills a gap: reordered, no longer lost) from a late duplicate.
_SEQ_WINDOW = 64
_SEQ_MASK = (1 << _SEQ_WINDOW) - 1

Event = tuple[int, str, str, str]


def _copy_cartesian(src: CartesianCommand, dst: CartesianCommand) -> None:
    dst.pose_m[:] = src.pose_m
    dst.stiffness_npm_nmprad[:] = src.stiffness_npm_nmprad
    dst.damping_ratio[:] = src.damping_ratio
    dst.wrench_n_nm[:] = src.wrench_n_nm


class FriRobot(RobotDriver):
    """The remote side of FRI 1.x over UDP (see the module docstring).

    Args:
        settings: the rig's ``[robot]`` table: addresses, answer policy and timeouts.
        where: how errors name that table (a rig file and table,
            ``"rigs/lwr4-lab.toml: robot"``); an error names ``<where>.<field>``.

    Raises:
        AddressError: ``settings.robot_ip`` is not an address.
    """

    def __init__(self, settings: FriRobotConfig, where: str = "robot") -> None:
        self.settings = settings
        self.where = where
        self.robot_ip = resolve_ipv4(f"{where}.robot_ip", settings.robot_ip)
        self._sock: socket.socket | None = None
        self._thread: threading.Thread | None = None
        self._cond = threading.Condition()
        self._stop = False
        self._connected = False
        self._error: DriverError | None = None
        self._listeners: list[Callable[[FriMeasurement], None]] = []
        # cycle hand-over (guarded by _cond)
        # the I/O thread fills _io (its own) and copies it to _msr under the lock: the
        # current cycle's measurement; the runner takes a copy of it (no allocation
        # on the I/O path)
        self._io = RemoteMeasurement()
        self._msr = RemoteMeasurement()
        self._have_msr = False
        self._pending = False
        self._cycle = 0
        self._runner_cycle = -1
        self._answered = True
        self._reply_addr: tuple[str, int] | None = None
        self._reply_refl = 0
        self._lockstep = False
        self._t_rx = 0
        self._last_rx_ns = 0
        self._last_time_ns = 0
        self._last_cycle_ns = 5_000_000
        # commands: the runner's last intent (a copy), the wire command, the runner's view
        self._user = CartesianCommand()
        self._have_user = False
        self._fri = FriCommand()
        self._wire = CmdArrays()
        self._pb = new_cmd_buffer()
        self._check = CmdArrays()
        self._check_pb = new_cmd_buffer()
        self._check_fri = FriCommand()
        self._applied_fri = FriCommand()
        self._applied = AppliedCommand(extras=self._applied_fri)
        self._send_seq = 0
        self._last_reply = bytearray(len(self._pb.raw))
        self._have_reply = False
        self._n = LinkCounters()
        self._watch = LinkWatch()
        self._events: list[Event] = []  # for the runner's next measurement (under _cond)
        # sequence
        self._last_seq: int | None = None
        self._seen = 0  # bit k: sequence number last_seq - k was received
        self._span = 0  # how many of those bits are known (since the first packet)
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
            self._sock = bind_udp(f"{self.where}.port", s.bind_host, s.port)
            self._sock.settimeout(s.poll_s)
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

    @property
    def decode_stats(self) -> DecodeStats:
        """Codec outcome counts of the robot's datagrams (live object)."""
        return self._n.decode

    def add_listener(self, callback: Callable[[FriMeasurement], None]) -> None:
        """Call ``callback(m)`` from the I/O thread for every accepted measurement."""
        self._listeners.append(callback)

    # ------------------------------------------------------------ runner side
    @requires_open(_WHAT)
    def measurements(self) -> Iterator[RobotState]:
        """One :class:`RobotState` per KRC cycle (``extras``: the :class:`FriMeasurement`)."""
        return self._measurements()

    def _measurements(self) -> Iterator[RobotState]:
        s = self.settings
        while True:
            with self._cond:
                first = self._n.accepted == 0
                limit = s.connect_timeout_s if first else s.cycle_timeout_s
                end = time.monotonic() + limit
                while not self._pending and not self._stop and self._error is None:
                    remaining = end - time.monotonic()
                    if remaining <= 0.0:
                        break
                    self._cond.wait(remaining)
                if self._error is not None:
                    raise self._error
                if self._stop:
                    return
                if not self._pending:
                    raise self._timeout_error(first, limit)
                m = RemoteMeasurement()
                copy_measurement(self._msr, m)
                self._pending = False
                self._runner_cycle = self._cycle
                if self._events:
                    m.link_events.extend(self._events)
                    self._events.clear()
            if m.error != 0 and m.state != FriState.CMD:
                # the KRC left command mode with an error (e.g. a software limit
                # switch): it holds the arm and will not resume until acknowledged
                raise DriverError(f"the KRC left command mode: {describe_error(m.error)}")
            yield robot_state_from_fri(m)

    def _timeout_error(self, first: bool, limit: float) -> DriverError:
        port = self._sock.getsockname()[1] if self._sock is not None else self.settings.port
        if first:
            return DriverTimeoutError(
                f"no FRI measurement from {self.robot_ip} on UDP port {port} within "
                f"{limit:g} s: {self._what_arrived()} (check FRIHOST/FRISOCK in the KRC's "
                "dlrrc.ini, friOpen, the rig's robot address and the firewall)"
            )
        return LinkLostError(
            f"FRI link to {self.robot_ip} lost: no packet on UDP port {port} for {limit:g} s"
        )

    def _what_arrived(self) -> str:
        """What did come on the port, in words (caller holds ``_cond``)."""
        n = self._n
        if n.received == 0:
            return "received nothing"
        said = []
        if n.foreign:
            host, fport = n.foreign_address or ("?", 0)
            said.append(f"{n.foreign} datagram{'s' if n.foreign > 1 else ''} from another "
                        f"address (last {host}:{fport}), dropped")
        bad = {k: v for k, v in n.decode.as_dict().items() if k != "ok" and v}
        if bad:
            said.append(f"{sum(bad.values())} datagrams from {self.robot_ip} that are not "
                        "FRI measurements (" + ", ".join(f"{k} {v}" for k, v in bad.items())
                        + ")")
        if n.implausible:
            said.append(f"{n.implausible} measurements with impossible contents")
        return "received " + "; ".join(said) if said else f"received {n.received} datagrams"

    @requires_open(_WHAT)
    def send(self, command: CartesianCommand | None) -> AppliedCommand:
        """Answer the current cycle with ``command`` (``None``: hold); see the module docstring.

        Returns what the KRC gets, valid until the next ``send()`` (the
        driver reuses the object; copy it to keep it). ``command`` is copied.

        Raises:
            PacketEncodeError: ``command`` holds NaN or infinite values
                (nothing is sent; the previous command stays in force).
        """
        check = self._check_fri
        with self._cond:
            if self._have_msr:
                # validate on a private copy first: never put NaN on the wire
                copy_fri_command(self._fri, check)
                to_fri_command(command, self._msr, check)
                command_to_arrays(check, self._check)
                pack_cmd(self._check, self._check_pb)
        applied, out = self._applied, self._applied_fri
        with self._cond:
            if command is None:
                self._have_user = False
            else:
                _copy_cartesian(command, self._user)
                self._have_user = True
            msr = self._msr
            if not self._have_msr:  # before the first measurement: the command waits for it
                copy_fri_command(self._fri, out)
                status = ApplyStatus.LATE | (
                    ApplyStatus.HELD if command is None else ApplyStatus.APPLIED
                )
                applied_from_fri(out, status, applied)
                if command is not None:
                    _copy_cartesian(command, applied.command)
                return applied
            status = to_fri_command(self._intent(), msr, self._fri)
            if self._runner_cycle == self._cycle and not self._answered:
                self._answer_locked()
                self._n.runner_answers += 1
                self._cond.notify_all()
            elif self.settings.answer_deadline_cycles > 0.0 or self._lockstep:
                self._n.runner_late += 1
                status |= ApplyStatus.LATE
            copy_fri_command(self._fri, out)
        return applied_from_fri(out, status, applied)

    def _intent(self) -> CartesianCommand | None:
        return self._user if self._have_user else None

    # ------------------------------------------------------------ clock & stats
    def now_ns(self) -> int | None:
        """The KRC's time now, estimated from the last measurement (``None`` before one).

        The wall time since that packet is added, at most one cycle; in lockstep,
        where wall time means nothing, none is (the time of the last measurement:
        what a lockstep emulator's F/T box has sent by then is stamped up to it,
        the same every run).
        """
        with self._cond:
            if self._n.accepted == 0:
                return None
            if self._lockstep:
                return self._last_time_ns
            since = time.perf_counter_ns() - self._last_rx_ns
            return self._last_time_ns + min(max(since, 0), self._last_cycle_ns)

    def turnarounds_ns(self) -> NDArray[np.int64]:
        """Receive -> answer times of the answered cycles so far (up to the last 131072)."""
        with self._cond:
            return self._n.turnarounds_ns()

    @property
    def stats(self) -> LinkStats:
        with self._cond:
            return self._n.snapshot()

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
        n = self._n
        while not self._stop:
            try:
                size, addr = sock.recvfrom_into(buf)
            except TimeoutError:
                continue
            except OSError as exc:
                if not self._stop:
                    with self._cond:
                        self._error = LinkLostError(f"FRI socket failed: {exc}")
                        self._cond.notify_all()
                return
            t_rx = clock()
            n.received += 1
            if addr[0] != robot_ip or (robot_port is not None and addr[1] != robot_port):
                if n.on_foreign(addr):
                    with self._cond:
                        self._events.append(
                            (self._last_time_ns, "WARNING", "link",
                             f"datagrams from {addr[0]}:{addr[1]} dropped: not the robot "
                             f"({robot_ip}" + (f":{robot_port}" if robot_port else "") + ")"))
                continue
            if decode_msr_into(view[:size], msr, stats=n.decode) is not DecodeStatus.OK:
                continue
            try:
                self._on_measurement(msr, addr, t_rx)
            except OSError as exc:  # sendto failed (network down)
                with self._cond:
                    self._error = LinkLostError(f"FRI answer to {addr[0]}:{addr[1]} failed: {exc}")
                    self._cond.notify_all()
                return

    def _accept_seq(self, msr: MsrArrays, addr: tuple[str, int]) -> bool:
        """Track ``sendSeqCount``; False: a duplicate (re-answered), stale or implausible packet.

        The last :data:`_SEQ_WINDOW` sequence numbers are remembered: a packet older
        than the newest one that fills a gap is counted reordered and no longer
        lost; one that was already received is a (late) duplicate.
        """
        n, s = self._n, self.settings
        seq = msr.send_seq
        first = self._last_seq is None
        delta = 1
        event = SeqEvent.NEXT
        if self._last_seq is not None:
            event, delta = classify_seq(seq, self._last_seq)
            if event is SeqEvent.DUPLICATE:
                self._duplicate(addr)
                return False
            if event is SeqEvent.STALE:
                age = -delta
                if age <= s.restart_seq_jump:
                    if age < self._span:  # (older than the first: only reordered)
                        bit = 1 << age
                        if self._seen & bit:
                            # an old packet again: not passed on, never re-answered
                            n.duplicates += 1
                            return False
                        self._seen |= bit
                        n.lost -= 1
                    n.stale += 1
                    return False
                n.restarts += 1
                delta = 1
        if not (
            s.min_cycle_s <= msr.msr_sample_time <= s.max_cycle_s
            and np.isfinite(msr.cmd_jnt_pos).all()
            and np.isfinite(msr.cmd_jnt_pos_fri_offset).all()
            and np.isfinite(msr.cmd_cart_pos).all()
        ):
            # a KRC never sends this; the packet cannot be mirrored or timed
            n.implausible += 1
            return False
        self._last_seq = seq
        if first:
            self._unwrapped = seq
            self._time_base_seq = seq
            self._seen, self._span = 1, 1
        else:
            if event is SeqEvent.GAP:
                n.lost += delta - 1
            self._unwrapped += delta
            self._seen = ((self._seen << delta) | 1) & _SEQ_MASK
            self._span = min(self._span + delta, _SEQ_WINDOW)
        return True

    def _duplicate(self, addr: tuple[str, int]) -> None:
        n = self._n
        n.duplicates += 1
        if self._have_reply and self._sock is not None:
            self._sock.sendto(self._last_reply, addr)
            n.answers += 1

    def _on_measurement(self, msr: MsrArrays, addr: tuple[str, int], t_rx: int) -> None:
        if not self._accept_seq(msr, addr):
            return
        cycle_ns = cycle_ns_from_seconds(msr.msr_sample_time)
        if cycle_ns != self._last_cycle_ns:
            self._time_base_ns = self._time_ns(self._last_cycle_ns)
            self._time_base_seq = self._unwrapped
            self._last_cycle_ns = cycle_ns
        time_ns = self._time_ns(cycle_ns)
        m = self._io
        fill_measurement(msr, self._unwrapped, time_ns, m)
        for listener in self._listeners:
            listener(m)
        s = self.settings
        lockstep = self._lockstep = (
            s.follow_lockstep_marker and int(msr.krl_int[LOCKSTEP_INDEX]) == LOCKSTEP_MARKER
        )
        with self._cond:
            self._n.on_measurement(m)
            if self._pending:  # it supersedes one the runner never took: in its own counters
                self._n.skipped += 1
            self._watch.see(m, self._events)
            self._n.fill(m)
            self._last_rx_ns = t_rx
            self._last_time_ns = time_ns
            copy_measurement(m, self._msr)
            self._pending = self._have_msr = True
            self._cycle += 1
            self._answered = False
            self._reply_addr = addr
            self._reply_refl = msr.send_seq
            self._t_rx = t_rx
            self._cond.notify_all()
            if lockstep:
                wait_s = s.runner_timeout_s
            else:
                wait_s = s.answer_deadline_cycles * cycle_ns * 1e-9
            if wait_s > 0.0:
                end = time.monotonic() + wait_s
                while not self._answered and not self._stop:
                    remaining = end - time.monotonic()
                    if remaining <= 0.0:
                        break
                    self._cond.wait(remaining)
            if not self._answered and not self._stop:
                # the runner's last intent, against this cycle's measurement
                to_fri_command(self._intent(), m, self._fri)
                self._answer_locked()
                if wait_s > 0.0:
                    self._n.deadline_answers += 1

    def _time_ns(self, cycle_ns: int) -> int:
        return self._time_base_ns + (self._unwrapped - self._time_base_seq) * cycle_ns

    def _answer_locked(self) -> None:
        """Send :attr:`_fri` as the answer of the current cycle (caller holds ``_cond``)."""
        sock, addr = self._sock, self._reply_addr
        if sock is None or addr is None:
            return
        wire = self._wire
        command_to_arrays(self._fri, wire)
        wire.send_seq = self._send_seq
        wire.refl_seq = self._reply_refl
        pack_cmd(wire, self._pb)
        sock.sendto(self._pb.raw, addr)
        self._n.on_answer(time.perf_counter_ns() - self._t_rx)
        self._send_seq = seq_next(self._send_seq)
        self._last_reply[:] = self._pb.raw  # for a duplicate measurement (same length)
        self._have_reply = True
        self._answered = True
