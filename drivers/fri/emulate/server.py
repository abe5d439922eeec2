"""The controller side of FRI 1.x over UDP, wrapping a :class:`SimWorld` (``ffexp emulate``).

What it does each cycle, as a KRC2 LR with a KRL script would:

1. send the measurement packet of the world's current state to the remote
   (state, quality and link statistics filled in by the emulator);
2. wait for the command whose ``reflSeqCount`` is this packet's
   ``sendSeqCount``: in **lockstep** pacing until it comes (or
   ``lockstep_timeout_s``, then a miss); in **real-time** pacing until 95 %
   of a cycle after the packet was sent (a KRC sends on its clock; when this
   process wakes late and sends late, the remote still gets its whole budget,
   and the late send is counted in ``late_sends``, not as the remote's miss;
   on Linux a reply is timed by the kernel's receive
   stamp, ``SO_TIMESTAMPNS``, so one that came while the world was stepping is
   not counted late by the step's duration; elsewhere by when it is read);
3. account the cycle in the link state machine (:class:`~drivers.fri.link.KrcLink`:
   statistics over the last 100 packets, quality, the KRL script's
   MON/CMD rule) and step the world with the arm command the KRC takes
   (:mod:`drivers.fri.emulate.krc`; a missed command is bridged: the world
   holds the last one).

Lockstep steps the world right after the answer, and the answer to packet k
acts from the step ``fri.command_delay_cycles`` later
(:class:`~drivers.fri.emulate.krc.CommandDelay`, 1 as on a real KRC; 0: the
step right after it), exactly like the in-process sim. Real time is pipelined
like a controller that interpolates: the world's step for the next packet
runs while the remote is answering, with the command that answered the
previous packet, so the remote has the whole cycle to answer and the answer
to packet k shapes packet k+2 (one cycle of transport delay).

State machine: :mod:`drivers.fri.link` (MON until ``start_cycles``
consecutive answered cycles with quality PERFECT, then CMD; back to MON on
UNACCEPTABLE or ``max_consecutive_misses`` misses in a row, with a stop:
that cycle the world gets "hold the measured pose, no superposed wrench or
torque" instead of the remote's command). In MON the KRC takes no command
(the world holds the last ones). In lockstep the emulator does not advance the world before the
remote has answered once: it re-sends the first packet (same sequence number)
every ``lockstep_timeout_s`` until an answer comes.

Commands: each command datagram is applied at most once (its
``sendSeqCount`` is remembered; duplicates and answers to older packets are
counted and dropped). The control strategy comes from ``krl.intData[0]``
(see :mod:`drivers.fri.convert`).

Fault injection (:mod:`drivers.emulate.faults`, seeded; from the first
``friStart`` on unless ``faults_from_start``; in lockstep a reorder is only
a delay: nothing else is in flight).

Software limit switches (:func:`~drivers.fri.emulate.krc.software_limit_error`,
``software_limits_deg``): a joint at its limit after a step makes the KRC
leave CMD with the error latched in every following measurement (``error``
bits, :data:`~drivers.fri.link.ERROR_SOFTWARE_LIMIT`); the next step brakes
the arm where it is (:func:`~drivers.fri.emulate.krc.brake_command`) and it stays
held; CMD does not start again while the error is latched.

The world's F/T samples of each cycle go to an optional
:class:`~drivers.emulate.netft_box.NetFtServer` after the step.
"""

from __future__ import annotations

import select
import socket
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Final, Literal

import numpy as np

from drivers.emulate.faults import FaultCounters, FaultSettings, FaultyLink
from drivers.emulate.netft_box import NetFtServer
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
from drivers.fri.emulate.krc import (
    SOFTWARE_LIMITS_DEG,
    CommandDelay,
    arm_command_from_fri,
    brake_command,
    control_mode,
    fri_measurement,
    plausible_command,
    software_limit_error,
    software_limits_rad,
    stop_command,
)
from drivers.fri.link import KrcLink, LinkEvent, QualityThresholds
from drivers.fri.types import FriCommand, FriMeasurement, FriQuality, FriState
from drivers.net.udp import bind_udp, enable_kernel_stamps, kernel_stamp_ns
from drivers.world.arm import ArmCommand
from drivers.world.world import SimWorld

__all__ = [
    "EmulatorSettings",
    "EmulatorStats",
    "FriEmulator",
]

_RESTART_JUMP: Final = 100

@dataclass(frozen=True)
class EmulatorSettings:
    """The emulated KRC.

    Args:
        remote: the remote's address (``FRIHOST``, ``FRISOCK``).
        port: local UDP port the KRC sends from (0: any free port).
        port_field: how an error names ``port`` (e.g. ``"rigs/emulator.toml: robot.port"``).
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
        software_limits_deg: the KRC's software limit switches A1..A7 [deg].
    """

    remote: tuple[str, int]
    port: int = 0
    port_field: str = "EmulatorSettings.port"
    bind_host: str = "0.0.0.0"
    pacing: Literal["realtime", "lockstep"] = "realtime"
    lockstep_timeout_s: float = 1.0
    start_cycles: int = 100
    max_consecutive_misses: int = 5
    faults: FaultSettings = field(default_factory=FaultSettings)
    faults_from_start: bool = False
    quality: QualityThresholds = field(default_factory=QualityThresholds)
    software_limits_deg: tuple[float, ...] = SOFTWARE_LIMITS_DEG


@dataclass
class EmulatorStats(FaultCounters):
    """Counters of an emulator run (with those of the injected faults)."""

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
    """Commands answering an older packet, or arriving after the answer budget, dropped."""
    duplicates: int = 0
    stale: int = 0
    foreign: int = 0
    applied: int = 0
    """Commands applied to the world (each at most once)."""
    invalid: int = 0
    """Commands the world refused (non-finite values, unknown strategy): back to MON."""
    starts: int = 0
    fallbacks: int = 0
    limit_stops: int = 0
    """Stops at a software limit switch (each also a fallback when in CMD)."""
    overruns: int = 0
    """Real time: cycles the emulator itself started late by more than a cycle."""
    late_sends: int = 0
    """Real time: measurements the emulator sent more than a tenth of a cycle after
    their scheduled time (its own scheduling; a KRC's clock never is)."""
    send_lateness_max_s: float = 0.0
    """Real time: the latest of those sends, after its scheduled time [s]."""
    misses_after_late_send: int = 0
    """Real time: missed cycles whose measurement had been sent late."""
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
            f"starts {self.starts}, fallbacks {self.fallbacks}, overruns {self.overruns}, "
            f"late sends {self.late_sends} (latest {self.send_lateness_max_s * 1e3:.2f} ms, "
            f"misses after one {self.misses_after_late_send}); "
            f"state {self.state.name}, quality {self.quality.name}"
        )


@dataclass(frozen=True)
class _Plan:
    """What one world step does: the interface state during it, the command, its sequence."""

    step_state: FriState
    command: FriCommand | None
    seq: int | None
    stop: bool = False


class FriEmulator:
    """A KRC2 LR with FRI, served over UDP from a :class:`SimWorld` (module docstring).

    Args:
        world: the simulated rig.
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
        self.krc = KrcLink(
            self.cycle_s,
            start_cycles=settings.start_cycles,
            max_consecutive_misses=settings.max_consecutive_misses,
            thresholds=settings.quality,
            timing=not self.lockstep,
        )
        self.sock = bind_udp(settings.port_field, settings.bind_host, settings.port)
        self.sock.setblocking(False)
        self.link = FaultyLink(self.sock, settings.faults, self.cycle_s, self.stats)
        self.link.active = settings.faults_from_start
        self._soft_limits_rad = software_limits_rad(settings.software_limits_deg)
        self._brake = False
        # lockstep: the KRC's command timing (real time: the pipeline and the link are the delay)
        self.delay = CommandDelay(world.scene.fri.command_delay_cycles if self.lockstep else 0)
        self._seq = world.cycle & 0xFFFF
        self._awaiting = -1
        self._answer_dropped = False  # the injector dropped the answer to the awaited packet
        self._last_cmd_seq: int | None = None
        self._msr = MsrArrays()
        self._pb = new_msr_buffer()
        self._cmd = CmdArrays()
        self._buf = bytearray(2048)
        self._stamped = enable_kernel_stamps(self.sock)
        self._found_wall_ns = 0  # kernel arrival stamp of the command found (0: none)
        self.step_time_s = 0.0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None

    @property
    def state(self) -> FriState:
        """The interface state the KRC reports (MON/CMD)."""
        return self.krc.state

    @property
    def quality(self) -> FriQuality:
        """The link quality the KRC reports."""
        return self.krc.quality

    @property
    def measurement(self) -> FriMeasurement:
        """The measurement of the world's current state, as the next packet reports it."""
        m = fri_measurement(self.world.last_state, self.cycle_s, self.krc.state, self.krc.quality,
                            self.krc.error)
        m.answer_rate, m.latency_s, m.jitter_s, m.miss_rate = self.krc.rates()
        m.miss_counter = self.stats.miss_counter
        return m

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
            delivered = self.link.send(data, self.settings.remote, t_send)
            st.sent += 1
            late_send = False
            if not self.lockstep:
                lateness = t_send - t_cycle
                st.send_lateness_max_s = max(st.send_lateness_max_s, lateness)
                if lateness > 0.1 * cycle:
                    st.late_sends += 1
                    late_send = True
            self._awaiting = self._seq
            # lockstep: a measurement the injector dropped cannot be answered, nor an
            # answer it dropped arrive: the cycle is a miss at once (a full wait's outcome)
            self._answer_dropped = not delivered
            self._seq = seq_next(self._seq)
            if self.lockstep:
                cmd, t_rx = self._wait_command(t_send + self.settings.lockstep_timeout_s)
                while cmd is None and waiting_first and not self._stop.is_set():
                    self._answer_dropped = False  # the remote may not be up yet: wait whole
                    self.link.send(data, self.settings.remote, time.perf_counter())
                    cmd, t_rx = self._wait_command(time.perf_counter()
                                                   + self.settings.lockstep_timeout_s)
                if self._stop.is_set() and cmd is None:
                    break
                waiting_first = False
                self._execute(self._decide(cmd, max(t_rx - t_send, 1e-9)))
            else:
                # pipelined: the physics of this cycle runs while the remote
                # answers; its answer is applied in the next cycle's step. A
                # prompt answer (first 30 % of the cycle) is awaited before the
                # step, so that its latency is measured, not the step's duration.
                # the remote's budget runs from when the packet left: a KRC sends on
                # its clock, so an emulator that wakes late (its own scheduling,
                # counted in late_sends) must not charge that to the remote
                end = t_send + 0.95 * cycle
                cmd, t_rx = self._wait_command(min(t_send + 0.3 * cycle, end))
                self._execute(plan)
                if cmd is None:
                    cmd, t_rx = self._wait_command(end)
                if cmd is not None and t_rx > end:  # it arrived after the budget and was
                    st.late += 1                      # read late (the emulator was): a miss
                    cmd = None
                if cmd is None and late_send:
                    st.misses_after_late_send += 1
                plan = self._decide(cmd, max(t_rx - t_send, 1e-9))
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
        m = fri_measurement(self.world.last_state, self.cycle_s, self.krc.state, self.krc.quality,
                            self.krc.error)
        a = self._msr
        measurement_to_arrays(m, a)
        ar, lat, jit, mr = self.krc.rates()
        a.answer_rate, a.latency, a.jitter, a.miss_rate = ar, lat, jit, mr
        a.miss_counter = self.stats.miss_counter & 0xFFFFFFFF
        a.msr_sample_time = self.cycle_s
        a.cmd_sample_time = self.cycle_s
        a.send_seq = self._seq
        a.refl_seq = self._last_cmd_seq or 0
        if self.lockstep:
            a.krl_int[LOCKSTEP_INDEX] = LOCKSTEP_MARKER
        return encode_msr(a, self._pb)

    def _wait_command(self, deadline: float) -> tuple[FriCommand | None, float]:
        """Serve the sockets until this cycle's command arrives or ``deadline``."""
        sock = self.sock
        netft = self.netft
        socks: list[socket.socket | NetFtServer] = [sock] if netft is None else [sock, netft]
        while True:
            now = time.perf_counter()
            self.link.flush(now)
            got = self._read_commands()
            if got is not None:
                t = time.perf_counter()
                if self._found_wall_ns:  # arrived that long before now
                    t -= max(0, time.time_ns() - self._found_wall_ns) * 1e-9
                return got, t
            if now >= deadline or self._stop.is_set() or (self._answer_dropped
                                                          and self.lockstep):
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

    def _read_commands(self) -> FriCommand | None:
        """Drain the socket; return the command answering the current packet, if one came."""
        with np.errstate(invalid="ignore"):  # signalling NaNs in hostile packets
            return self._read_commands_inner()

    def _read_commands_inner(self) -> FriCommand | None:
        st = self.stats
        remote = self.settings.remote
        view = memoryview(self._buf)
        found: FriCommand | None = None
        while True:
            wall_ns = 0
            try:
                if self._stamped:
                    n, anc, _flags, addr = self.sock.recvmsg_into([self._buf], 64)
                    wall_ns = kernel_stamp_ns(anc)
                else:
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
                # its reflSeqCount (header bytes 2-3): the answer to the packet awaited?
                if n >= 4 and int.from_bytes(view[2:4], "little") == self._awaiting:
                    self._answer_dropped = True
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
            found = arrays_to_command(a, control_mode(self.world.mode))
            self._found_wall_ns = wall_ns

    def _decide(self, cmd: FriCommand | None, latency_s: float) -> _Plan:
        """Statistics, quality and the script's state machine; what the next step does."""
        st, krc = self.stats, self.krc
        answered = cmd is not None
        was_commanding = krc.commanding
        event = krc.cycle(answered, latency_s)
        if answered:
            st.answered += 1
        else:
            st.missed += 1
            st.miss_counter += 1
        if event is LinkEvent.FALLBACK:
            st.fallbacks += 1
            return _Plan(FriState.CMD, None, None, stop=True)
        if was_commanding and cmd is None:
            st.bridged += 1
        if event is LinkEvent.START:
            st.starts += 1
            self.link.active = True
        if cmd is not None and krc.commanding:
            if not plausible_command(cmd):
                st.invalid += 1
                st.fallbacks += 1
                krc.refuse()
                return _Plan(FriState.MON, None, None)
            return _Plan(FriState.CMD, cmd, self._last_cmd_seq)
        return _Plan(krc.state, None, None)

    def _execute(self, plan: _Plan) -> None:
        """One world step as planned."""
        if self._brake:  # stopped at a software limit switch: the brakes
            self._brake = False
            self.delay.clear()
            self._step(brake_command(self.world.last_state), None)
        elif plan.stop:  # leaving CMD: hold the measured pose, no superposed wrench/torque
            self.delay.clear()
            self._step(stop_command(self.world.last_state), None)
        else:
            self._step(plan.command, plan.seq)

    def _step(self, cmd: FriCommand | ArmCommand | None, seq: int | None) -> None:
        st = self.stats
        world = self.world
        t0 = time.perf_counter()
        try:
            arm = arm_command_from_fri(cmd, world.mode) if isinstance(cmd, FriCommand) else cmd
            if isinstance(cmd, FriCommand) or cmd is None:  # the remote's: CommandDelay
                arm, seq = self.delay.push(arm, seq)
                cmd = arm
            world.advance(arm)
        except InvalidCommandError:
            # the KRC refuses such a command and leaves command mode
            st.invalid += 1
            if self.krc.commanding:
                st.fallbacks += 1
            self.krc.refuse()
            self.delay.clear()
            world.advance(None)
            cmd = None
            seq = None
        if cmd is not None and seq is not None:
            st.applied += 1
            st.applied_seqs.append(seq)
        st.cycles += 1
        if not self.krc.error:
            error = software_limit_error(world.data.qpos[:7], self._soft_limits_rad)
            if error:
                st.limit_stops += 1
                if self.krc.fault(error) is LinkEvent.FALLBACK:
                    st.fallbacks += 1
                self._brake = True
        if self.netft is not None:
            self.netft.publish(world.ft_samples())
        else:
            world.ft_samples()
        self.step_time_s = time.perf_counter() - t0
