"""The controller side of FRI 1.x over UDP, wrapping a :class:`SimWorld` (``ffexp emulate``).

What it does each cycle, as a KRC2 LR with a KRL script would:

1. send the measurement packet of the world's current state to the remote
   (state, quality and link statistics filled in by the emulator);
2. wait for the command whose ``reflSeqCount`` is this packet's
   ``sendSeqCount``: in **lockstep** pacing until it comes (or
   ``lockstep_timeout_s``, then a miss); in **real-time** pacing until 95 %
   of the cycle has passed (a reply read after the world's step is stamped
   when it is read, so latencies above 30 % of the cycle are overestimated
   by up to the step's duration);
3. update the statistics over the last 100 packets (:class:`LinkWindow`) and
   the quality (:class:`QualityThresholds`), run the KRL script's state
   machine, and step the world with the command (a missed command is
   bridged: the world holds the last one).

Lockstep steps the world right after the answer, so the answer to packet k
shapes packet k+1, exactly like the in-process sim. Real time is pipelined
like a controller that interpolates: the world's step for the next packet
runs while the remote is answering, with the command that answered the
previous packet, so the remote has the whole cycle to answer and the answer
to packet k shapes packet k+2 (one cycle of transport delay).

State machine (the script ``friOpen(ms)``; ``WAIT FOR $FriQuality ==
#PERFECT``; ``friStart(1.0)``; a loop that waits for the interface to leave
#CMD and starts again): the first packet is MON; after ``start_cycles``
(100) consecutive answered cycles with quality PERFECT the state goes to CMD;
in CMD, quality UNACCEPTABLE or ``max_consecutive_misses`` misses in a row
make it fall back to MON (the KRC's own rule), with a stop: that cycle the
world gets "hold the measured pose, no superposed wrench or torque" instead
of the remote's command. In MON the world ignores commands (it holds the
last ones). In lockstep the emulator does not advance the world before the
remote has answered once: it re-sends the first packet (same sequence number)
every ``lockstep_timeout_s`` until an answer comes.

Commands: each command datagram is applied at most once (its
``sendSeqCount`` is remembered; duplicates and answers to older packets are
counted and dropped). The control strategy comes from ``krl.intData[0]``
(see :mod:`drivers.fri.convert`).

Fault injection (:class:`FaultSettings`, seeded; from the first ``friStart``
on unless ``faults_from_start``): every datagram in either
direction is lost with probability ``loss``; outgoing measurement datagrams
get a delay ``delay_s + |N(0, jitter_s)|``, are sent twice with probability
``duplicate``, held back one cycle (so the next overtakes them) with
probability ``reorder`` (in lockstep that is only a delay: nothing else is
in flight), and get 1-4 random bytes overwritten (each in the header with
probability 1/2) with probability ``corrupt``.

The world's F/T samples of each cycle go to an optional
:class:`~drivers.netft.emulator.NetFtServer` after the step.
"""

from __future__ import annotations

import heapq
import math
import select
import socket
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Final, Literal

import numpy as np

from drivers.base.types import CmdFlags, Command, FriQuality, FriState
from drivers.errors import InvalidCommandError
from drivers.fri.codec import (
    CmdArrays,
    DecodeStats,
    DecodeStatus,
    MsrArrays,
    SeqEvent,
    classify_seq,
    decode_cmd_into,
    encode_msr,
    new_msr_buffer,
    seq_next,
)
from drivers.fri.convert import (
    LOCKSTEP_INDEX,
    LOCKSTEP_MARKER,
    arrays_to_command,
    measurement_to_arrays,
)
from drivers.fri.udp import bind_udp
from drivers.netft.emulator import NetFtServer
from drivers.sim.world import SimWorld

__all__ = [
    "EmulatorSettings",
    "EmulatorStats",
    "FaultSettings",
    "FriEmulator",
    "LinkWindow",
    "QualityThresholds",
    "plausible_command",
    "quality_of",
]

WINDOW: Final = 100
#: Packets in the window before the link can be rated UNACCEPTABLE.
MIN_RATED: Final = 10
_RESTART_JUMP: Final = 100


@dataclass(frozen=True)
class FaultSettings:
    """Injected network faults (probabilities in 0..1, times in s)."""

    loss: float = 0.0
    delay_s: float = 0.0
    jitter_s: float = 0.0
    duplicate: float = 0.0
    reorder: float = 0.0
    corrupt: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("loss", "duplicate", "reorder", "corrupt"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"{name} must be a probability in 0..1, got {v}")
        if self.delay_s < 0 or self.jitter_s < 0:
            raise ValueError("delay and jitter must be >= 0")

    @property
    def any(self) -> bool:
        return any((self.loss, self.delay_s, self.jitter_s, self.duplicate, self.reorder,
                    self.corrupt))


@dataclass(frozen=True)
class QualityThresholds:
    """How the emulator rates the link over the last 100 packets (ours; KUKA's are not public).

    ``miss`` is the fraction of packets not answered in time; latency and
    jitter (mean and standard deviation of send -> answer) are in cycles and
    count only in real-time pacing.

    * PERFECT: a full window without a miss, latency <= ``perfect_latency``,
      jitter <= ``perfect_jitter``;
    * OK: miss <= ``ok_miss``, latency <= ``ok_latency``, jitter <= ``ok_jitter``;
    * BAD: miss <= ``bad_miss`` (commanding is still allowed);
    * UNACCEPTABLE: more misses than that (the KRC leaves command mode).

    An empty window, or one of fewer than 10 packets that would be
    UNACCEPTABLE, is BAD; a window not yet full is at most OK.
    """

    perfect_latency: float = 0.3
    perfect_jitter: float = 0.1
    ok_miss: float = 0.05
    ok_latency: float = 0.6
    ok_jitter: float = 0.2
    bad_miss: float = 0.25


class LinkWindow:
    """answerRate, latency, jitter, missRate over the last ``size`` packets."""

    def __init__(self, size: int = WINDOW) -> None:
        self.size = size
        self.answered = np.zeros(size, dtype=bool)
        self.latency = np.zeros(size)
        self.n = 0
        self.i = 0

    def add(self, answered: bool, latency_s: float) -> None:
        self.answered[self.i] = answered
        self.latency[self.i] = latency_s if answered else 0.0
        self.i = (self.i + 1) % self.size
        self.n = min(self.n + 1, self.size)

    def reset(self) -> None:
        self.n = 0
        self.i = 0

    def rates(self) -> tuple[float, float, float, float]:
        """``(answer_rate, latency_s, jitter_s, miss_rate)``; zeros for an empty window."""
        n = self.n
        if n == 0:
            return 0.0, 0.0, 0.0, 0.0
        ans = self.answered[:n] if n < self.size else self.answered
        lat = (self.latency[:n] if n < self.size else self.latency)[ans]
        k = int(ans.sum())
        rate = k / n
        mean = float(lat.mean()) if k else 0.0
        jitter = float(lat.std()) if k > 1 else 0.0
        return rate, mean, jitter, 1.0 - rate


def quality_of(
    window: LinkWindow, cycle_s: float, th: QualityThresholds, *, timing: bool
) -> FriQuality:
    """The quality for a window (see :class:`QualityThresholds`)."""
    if window.n == 0:
        return FriQuality.BAD
    _, lat, jit, miss = window.rates()
    lat_c, jit_c = lat / cycle_s, jit / cycle_s
    if miss > th.bad_miss:
        # a few packets say little: an early miss is BAD, not yet UNACCEPTABLE
        return FriQuality.UNACCEPTABLE if window.n >= MIN_RATED else FriQuality.BAD
    ok = miss <= th.ok_miss and (not timing or (lat_c <= th.ok_latency and jit_c <= th.ok_jitter))
    if not ok:
        return FriQuality.BAD
    perfect = (
        window.n == window.size
        and miss == 0.0
        and (not timing or (lat_c <= th.perfect_latency and jit_c <= th.perfect_jitter))
    )
    return FriQuality.PERFECT if perfect else FriQuality.OK


@dataclass(frozen=True)
class EmulatorSettings:
    """The emulated KRC.

    Args:
        remote: the remote's address (``FRIHOST``, ``FRISOCK``).
        port: local UDP port the KRC sends from (0: any free port).
        bind_host: local address.
        pacing: ``realtime`` (wall clock) or ``lockstep`` (advance on each answer).
        lockstep_timeout_s: lockstep: wait this long for an answer, then count a miss.
        start_cycles: consecutive answered cycles before ``friStart``.
        max_consecutive_misses: misses in a row that end command mode.
        faults: injected network faults.
        faults_from_start: inject them from the first packet; by default they
            start with the first ``friStart`` (a lossy link would otherwise
            never pass the script's wait for PERFECT quality).
        quality: thresholds of the quality rating.
    """

    remote: tuple[str, int]
    port: int = 0
    bind_host: str = "0.0.0.0"
    pacing: Literal["realtime", "lockstep"] = "realtime"
    lockstep_timeout_s: float = 1.0
    start_cycles: int = 100
    max_consecutive_misses: int = 5
    faults: FaultSettings = field(default_factory=FaultSettings)
    faults_from_start: bool = False
    quality: QualityThresholds = field(default_factory=QualityThresholds)


@dataclass
class EmulatorStats:
    """Counters of an emulator run."""

    cycles: int = 0
    """World steps."""
    sent: int = 0
    """Measurement packets handed to the network (before injected faults)."""
    answered: int = 0
    missed: int = 0
    bridged: int = 0
    """Missed cycles in CMD, bridged by holding the last command."""
    received: int = 0
    """Datagrams received on the KRC port (any source)."""
    late: int = 0
    """Commands answering an older packet, dropped."""
    duplicates: int = 0
    stale: int = 0
    foreign: int = 0
    applied: int = 0
    """Commands applied to the world (each at most once)."""
    invalid: int = 0
    """Commands the world refused (non-finite values, unknown strategy): back to MON."""
    starts: int = 0
    fallbacks: int = 0
    overruns: int = 0
    """Real time: cycles the emulator itself started late by more than a cycle."""
    dropped_out: int = 0
    dropped_in: int = 0
    duplicated: int = 0
    reordered: int = 0
    corrupted: int = 0
    decode: DecodeStats = field(default_factory=DecodeStats)
    state: FriState = FriState.OFF
    quality: FriQuality = FriQuality.BAD
    miss_counter: int = 0
    applied_seqs: deque[int] = field(default_factory=lambda: deque(maxlen=4096))
    """``sendSeqCount`` of the last applied commands (for checks)."""

    def summary(self) -> str:
        d = self.decode.as_dict()
        return (
            f"cycles {self.cycles}, sent {self.sent}, answered {self.answered}, "
            f"missed {self.missed} (bridged {self.bridged}), late {self.late}, "
            f"duplicates {self.duplicates}, stale {self.stale}, foreign {self.foreign}, "
            f"rejected {sum(d.values()) - d['ok']}, applied {self.applied}, "
            f"starts {self.starts}, fallbacks {self.fallbacks}, overruns {self.overruns}; "
            f"state {self.state.name}, quality {self.quality.name}"
        )


#: Largest command values the emulated KRC takes (beyond them it leaves command mode).
MAX_TCP_FORCE_N: Final = 1000.0
MAX_TCP_TORQUE_NM: Final = 200.0
MAX_JNT_TRQ_NM: Final = 500.0
MAX_REACH_M: Final = 2.0
MAX_STIFFNESS: Final = 1.0e5
MAX_DAMPING: Final = 10.0


def plausible_command(c: Command) -> bool:
    """Whether the fields ``c.flags`` selects are values a KRC would take.

    Finite, forces/torques and stiffnesses within generous bounds, a proper
    rotation in ``cart_pos`` within reach, joint angles within a turn.
    """
    f = int(c.flags)
    if f & CmdFlags.CARTPOS:
        p = c.cart_pos
        r = p[:3, :3]
        if not (np.isfinite(p).all() and np.abs(p[:3, 3]).max() <= MAX_REACH_M
                and np.abs(r.T @ r - np.eye(3)).max() <= 1e-3):
            return False
    if f & CmdFlags.JNTPOS and not (np.abs(c.jnt_pos) <= 2.0 * math.pi).all():
        return False
    if f & CmdFlags.TCPFT and not (
        (np.abs(c.add_tcp_ft[:3]) <= MAX_TCP_FORCE_N).all()
        and (np.abs(c.add_tcp_ft[3:]) <= MAX_TCP_TORQUE_NM).all()
    ):
        return False
    if f & CmdFlags.JNTTRQ and not (np.abs(c.add_jnt_trq) <= MAX_JNT_TRQ_NM).all():
        return False
    for flag, gains, top in (
        (CmdFlags.CARTSTIFF, c.cart_stiffness, MAX_STIFFNESS),
        (CmdFlags.JNTSTIFF, c.jnt_stiffness, MAX_STIFFNESS),
        (CmdFlags.CARTDAMP, c.cart_damping, MAX_DAMPING),
        (CmdFlags.JNTDAMP, c.jnt_damping, MAX_DAMPING),
    ):
        if f & flag and not ((gains >= 0.0) & (gains <= top)).all():
            return False
    return True


@dataclass(frozen=True)
class _Plan:
    """What one world step does: the interface state during it, the command, its sequence."""

    step_state: FriState
    command: Command | None
    seq: int | None
    stop: bool = False


class _FaultyLink:
    """Applies :class:`FaultSettings` to one UDP socket."""

    def __init__(self, sock: socket.socket, faults: FaultSettings, cycle_s: float,
                 stats: EmulatorStats) -> None:
        self.sock = sock
        self.f = faults
        self.cycle_s = cycle_s
        self.stats = stats
        self.rng = np.random.default_rng(faults.seed)
        self.queue: list[tuple[float, int, bytes, tuple[str, int]]] = []
        self._k = 0
        self.active = True

    def send(self, data: bytes, addr: tuple[str, int], now: float) -> None:
        f = self.f
        if not f.any or not self.active:
            self._sendto(data, addr)
            return
        rng = self.rng
        if f.loss and rng.random() < f.loss:
            self.stats.dropped_out += 1
            return
        if f.corrupt and rng.random() < f.corrupt:
            b = bytearray(data)
            for _ in range(int(rng.integers(1, 5))):
                # half of the damage in the 8-byte header, so that some is detectable
                end = 8 if rng.random() < 0.5 else len(b)
                b[int(rng.integers(0, end))] = int(rng.integers(0, 256))
            data = bytes(b)
            self.stats.corrupted += 1
        delay = f.delay_s + (abs(float(rng.normal(0.0, f.jitter_s))) if f.jitter_s else 0.0)
        if f.reorder and rng.random() < f.reorder:
            delay += self.cycle_s * 1.5
            self.stats.reordered += 1
        copies = 1
        if f.duplicate and rng.random() < f.duplicate:
            copies = 2
            self.stats.duplicated += 1
        for _ in range(copies):
            if delay <= 0.0:
                self._sendto(data, addr)
            else:
                self._k += 1
                heapq.heappush(self.queue, (now + delay, self._k, data, addr))

    def drop_incoming(self) -> bool:
        f = self.f
        if self.active and f.loss and self.rng.random() < f.loss:
            self.stats.dropped_in += 1
            return True
        return False

    def flush(self, now: float) -> None:
        q = self.queue
        while q and q[0][0] <= now:
            _, _, data, addr = heapq.heappop(q)
            self._sendto(data, addr)

    def next_due(self) -> float | None:
        return self.queue[0][0] if self.queue else None

    def _sendto(self, data: bytes, addr: tuple[str, int]) -> None:
        try:
            self.sock.sendto(data, addr)
        except OSError:
            pass  # remote port closed (ICMP) or no route: the KRC keeps sending


class FriEmulator:
    """A KRC2 LR with FRI, served over UDP from a :class:`SimWorld` (module docstring).

    Args:
        world: the simulated rig (its ``fri_state`` is driven by the emulator).
        settings: addresses, pacing, faults.
        netft: an emulated Net F/T box fed with the world's F/T samples.
    """

    def __init__(self, world: SimWorld, settings: EmulatorSettings,
                 netft: NetFtServer | None = None) -> None:
        self.world = world
        self.settings = settings
        self.netft = netft
        self.cycle_s = float(world.scene.fri.cycle)
        self.lockstep = settings.pacing == "lockstep"
        self.stats = EmulatorStats()
        self.window = LinkWindow()
        self.sock = bind_udp("--port", settings.bind_host, settings.port)
        self.sock.setblocking(False)
        self.link = _FaultyLink(self.sock, settings.faults, self.cycle_s, self.stats)
        self.link.active = settings.faults_from_start
        self.state = FriState.MON
        self.quality = FriQuality.BAD
        self._consecutive_ok = 0
        self._consecutive_miss = 0
        self._seq = world.cycle & 0xFFFF
        self._awaiting = -1
        self._last_cmd_seq: int | None = None
        self._msr = MsrArrays()
        self._pb = new_msr_buffer()
        self._cmd = CmdArrays()
        self._buf = bytearray(2048)
        self.step_time_s = 0.0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None
        world.fri_state = FriState.MON
        world.fri_quality = self.quality

    # ------------------------------------------------------------ lifecycle
    @property
    def address(self) -> tuple[str, int]:
        host, port = self.sock.getsockname()[:2]
        return str(host), int(port)

    def stop(self) -> None:
        """Ask :meth:`run` to return after the current cycle (thread-safe)."""
        self._stop.set()

    def close(self) -> None:
        self.stop()
        t = self._thread
        if t is not None and t is not threading.current_thread():
            t.join(timeout=5.0)
        self._thread = None
        self.sock.close()
        if self.netft is not None:
            self.netft.close()

    def start_thread(self, max_cycles: int | None = None) -> threading.Thread:
        """Run in a background thread (tests, benchmarks); :meth:`close` stops it."""

        def target() -> None:
            try:
                self.run(max_cycles=max_cycles)
            except BaseException as exc:  # reported by join()
                self._error = exc

        self._thread = threading.Thread(target=target, name="fri-emulator", daemon=True)
        self._thread.start()
        return self._thread

    def join(self, timeout: float | None = None) -> None:
        """Wait for the background thread; re-raise what it died of."""
        if self._thread is not None:
            self._thread.join(timeout)
        if self._error is not None:
            raise self._error

    # ------------------------------------------------------------ the loop
    def run(self, max_cycles: int | None = None,
            on_cycle: Callable[[FriEmulator], None] | None = None) -> EmulatorStats:
        """Serve until :meth:`stop` or ``max_cycles`` world steps; returns the counters."""
        st = self.stats
        cycle = self.cycle_s
        waiting_first = self.lockstep
        plan = _Plan(FriState.MON, None, None)
        t_cycle = time.perf_counter()
        while not self._stop.is_set():
            if max_cycles is not None and st.cycles >= max_cycles:
                break
            data = self._packet()
            t_send = time.perf_counter()
            self.link.send(data, self.settings.remote, t_send)
            st.sent += 1
            self._awaiting = self._seq
            self._seq = seq_next(self._seq)
            if self.lockstep:
                cmd, t_rx = self._wait_command(t_send + self.settings.lockstep_timeout_s)
                while cmd is None and waiting_first and not self._stop.is_set():
                    self.link.send(data, self.settings.remote, time.perf_counter())
                    cmd, t_rx = self._wait_command(time.perf_counter()
                                                   + self.settings.lockstep_timeout_s)
                if self._stop.is_set() and cmd is None:
                    break
                waiting_first = False
                self._execute(self._decide(cmd, t_rx - t_send))
            else:
                # pipelined: the physics of this cycle runs while the remote
                # answers; its answer is applied in the next cycle's step. A
                # prompt answer (first 30 % of the cycle) is awaited before the
                # step, so that its latency is measured, not the step's duration.
                end = t_cycle + 0.95 * cycle
                cmd, t_rx = self._wait_command(min(t_send + 0.3 * cycle, end))
                self._execute(plan)
                if cmd is None:
                    cmd, t_rx = self._wait_command(end)
                plan = self._decide(cmd, t_rx - t_send)
            if on_cycle is not None:
                on_cycle(self)
            if not self.lockstep:
                t_cycle += cycle
                now = time.perf_counter()
                if now > t_cycle + cycle:
                    st.overruns += 1
                    t_cycle = now
                self._idle_until(t_cycle)
        st.state, st.quality = self.state, self.quality
        return st

    def _packet(self) -> bytes:
        m = self.world.last_measurement
        a = self._msr
        measurement_to_arrays(m, a)
        a.state = self.state
        a.quality = self.quality
        ar, lat, jit, mr = self.window.rates()
        a.answer_rate, a.latency, a.jitter, a.miss_rate = ar, lat, jit, mr
        a.miss_counter = self.stats.miss_counter & 0xFFFFFFFF
        a.msr_sample_time = self.cycle_s
        a.cmd_sample_time = self.cycle_s
        a.send_seq = self._seq
        a.refl_seq = self._last_cmd_seq or 0
        if self.lockstep:
            a.krl_int[LOCKSTEP_INDEX] = LOCKSTEP_MARKER
        return encode_msr(a, self._pb)

    def _wait_command(self, deadline: float) -> tuple[Command | None, float]:
        """Serve the sockets until this cycle's command arrives or ``deadline``."""
        sock = self.sock
        netft = self.netft
        socks: list[socket.socket | NetFtServer] = [sock] if netft is None else [sock, netft]
        while True:
            now = time.perf_counter()
            self.link.flush(now)
            got = self._read_commands()
            if got is not None:
                return got, time.perf_counter()
            if now >= deadline or self._stop.is_set():
                return None, now
            due = self.link.next_due()
            until = deadline if due is None else min(deadline, due)
            r, _, _ = select.select(socks, [], [], max(0.0, min(until - now, 0.05)))
            if netft is not None and netft in r:
                netft.handle_requests()

    def _idle_until(self, t: float) -> None:
        """Real time: serve the sockets (late commands, Net F/T requests) until ``t``."""
        netft = self.netft
        socks: list[socket.socket | NetFtServer] = [self.sock] if netft is None else [
            self.sock, netft]
        while not self._stop.is_set():
            now = time.perf_counter()
            self.link.flush(now)
            if now >= t:
                return
            due = self.link.next_due()
            until = t if due is None else min(t, due)
            r, _, _ = select.select(socks, [], [], max(0.0, until - now))
            if self.sock in r:
                self._read_commands()  # anything now is late
            if netft is not None and netft in r:
                netft.handle_requests()

    def _read_commands(self) -> Command | None:
        """Drain the socket; return the command answering the current packet, if one came."""
        with np.errstate(invalid="ignore"):  # signalling NaNs in hostile packets
            return self._read_commands_inner()

    def _read_commands_inner(self) -> Command | None:
        st = self.stats
        remote = self.settings.remote
        view = memoryview(self._buf)
        found: Command | None = None
        while True:
            try:
                n, addr = self.sock.recvfrom_into(self._buf)
            except (BlockingIOError, InterruptedError):
                return found
            except OSError:  # ICMP port unreachable: the remote is not (yet) there
                continue
            st.received += 1
            if addr[0] != remote[0] or addr[1] != remote[1]:
                st.foreign += 1
                continue
            if self.link.drop_incoming():
                continue
            a = self._cmd
            if decode_cmd_into(view[:n], a, stats=st.decode) is not DecodeStatus.OK:
                continue
            s = a.send_seq
            if self._last_cmd_seq is not None:
                event, delta = classify_seq(s, self._last_cmd_seq)
                if event is SeqEvent.DUPLICATE:
                    st.duplicates += 1
                    continue
                if event is SeqEvent.STALE and -delta <= _RESTART_JUMP:
                    st.stale += 1
                    continue
            self._last_cmd_seq = s
            if a.refl_seq != self._awaiting or found is not None:
                st.late += 1
                continue
            found = arrays_to_command(a, self.world.control)

    def _decide(self, cmd: Command | None, latency_s: float) -> _Plan:
        """Statistics, quality and the script's state machine; what the next step does."""
        st, s = self.stats, self.settings
        answered = cmd is not None
        self.window.add(answered, latency_s)
        if answered:
            st.answered += 1
            self._consecutive_ok += 1
            self._consecutive_miss = 0
        else:
            st.missed += 1
            st.miss_counter += 1
            self._consecutive_ok = 0
            self._consecutive_miss += 1
        q = quality_of(self.window, self.cycle_s, s.quality, timing=not self.lockstep)
        self.quality = q
        if self.state == FriState.CMD:
            if q == FriQuality.UNACCEPTABLE or self._consecutive_miss >= s.max_consecutive_misses:
                st.fallbacks += 1
                self._consecutive_ok = 0
                self.state = FriState.MON
                return _Plan(FriState.CMD, None, None, stop=True)
            if cmd is None:
                st.bridged += 1
        elif (
            self.state == FriState.MON
            and self._consecutive_ok >= s.start_cycles
            and q == FriQuality.PERFECT
        ):
            self.state = FriState.CMD
            st.starts += 1
            self.link.active = True
        if cmd is not None and self.state == FriState.CMD:
            if not plausible_command(cmd):
                st.invalid += 1
                st.fallbacks += 1
                self.state = FriState.MON
                self._consecutive_ok = 0
                return _Plan(FriState.MON, None, None)
            return _Plan(FriState.CMD, cmd, self._last_cmd_seq)
        return _Plan(self.state, None, None)

    def _execute(self, plan: _Plan) -> None:
        """One world step as planned; the world's state is the emulator's afterwards."""
        world = self.world
        cmd = plan.command
        if plan.stop:  # leaving CMD: hold the measured pose, no superposed wrench/torque
            m = world.last_measurement
            cmd = Command(
                flags=CmdFlags.CARTPOS | CmdFlags.JNTPOS | CmdFlags.TCPFT | CmdFlags.JNTTRQ,
                control=m.control, jnt_pos=m.msr_jnt_pos.copy(), cart_pos=m.msr_cart_pos.copy(),
            )
        world.fri_state = plan.step_state
        world.fri_quality = self.quality
        self._step(cmd, plan.seq)
        world.fri_state = self.state

    def _step(self, cmd: Command | None, seq: int | None) -> None:
        st = self.stats
        t0 = time.perf_counter()
        try:
            self.world.step(cmd)
        except InvalidCommandError:
            # the KRC refuses such a command and leaves command mode
            st.invalid += 1
            if self.state == FriState.CMD:
                st.fallbacks += 1
            self.state = FriState.MON
            self._consecutive_ok = 0
            self.world.fri_state = FriState.MON
            self.world.step(None)
            cmd = None
            seq = None
        if cmd is not None and seq is not None:
            st.applied += 1
            st.applied_seqs.append(seq)
        st.cycles += 1
        if self.netft is not None:
            self.netft.publish(self.world.ft_samples())
        else:
            self.world.ft_samples()
        self.step_time_s = time.perf_counter() - t0
