"""ATI Net F/T client over RDT/UDP, behind the :class:`ForceTorqueSensor` interface.

``start()`` binds a local port and asks the box (default port 49152) to
stream (``0x0002``, one record per datagram, or ``0x0003`` buffered);
``samples()`` drains every datagram that has arrived since the last call
without blocking (reading at the runner's pace never lets data pile up in
the socket: the whole queue is read each cycle), so it costs nothing when
the box is silent. Only datagrams from the box's address count; the rest are
dropped as foreign. Counts become N and N·m through the box's
counts-per-force/torque and units (:class:`~drivers.netft.codec.Calibration`,
from the rig's ``[ft]`` table: read ``cfgcpf``/``cfgcpt``/``scfgfu``/``scfgtu`` from
``http://<box>/netftapi2.xml``). Status words are passed through unchanged
(the runner aborts on the saturation bit 0x00020000).

While nothing arrives, ``samples()`` repeats the start request every
``resend_s`` (a request sent before the box was up is simply lost, as
rpi_ati_net_ft also found).

Sequence tracking on ``rdt_sequence``: gaps (lost datagrams), duplicates and
reordered (older) datagrams are counted, the last two dropped.

Time stamps: ``ft_sequence`` counts the box's internal samples
(``sample_rate_hz``). The first batch is anchored to ``clock()`` (the robot
driver's estimate of the controller's time, so that F/T and robot share one
clock; host monotonic time if none); later samples are placed by their
``ft_sequence``. If the stamps drift more than ``reanchor_s`` from the clock
(a wrong rate setting, a box restart) the client re-anchors and counts it.
"""

from __future__ import annotations

import contextlib
import select
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from drivers.base.guards import requires_open
from drivers.base.interfaces import ForceTorqueSensor
from drivers.base.types import FtSamples
from drivers.errors import ConfigError, NotConnectedError
from drivers.net.udp import bind_udp, resolve_ipv4
from drivers.netft.codec import (
    MAX_RECORDS,
    Calibration,
    RdtCommand,
    RdtDecodeStats,
    RdtDecodeStatus,
    RdtSamples,
    counts_to_si,
    decode_rdt_into,
    encode_request,
    rdt_seq_delta,
)
from drivers.netft.config import NetFtConfig

__all__ = ["NetFtClient", "NetFtConfig", "NetFtStats"]


@dataclass(frozen=True)
class NetFtStats:
    """Counters of the client, for logs."""

    datagrams: int
    foreign: int
    decode: dict[str, int]
    records: int
    lost: int
    """Datagrams missing in ``rdt_sequence``."""
    duplicates: int
    stale: int
    reanchors: int
    requests: int
    """Start requests sent (more than one: the box did not answer at once)."""
    last_status: int


class NetFtClient(ForceTorqueSensor):
    """The Net F/T box as a streaming sensor (see the module docstring).

    Args:
        settings: the rig's ``[ft]`` table: address, calibration, rate.
        clock: the time the samples are stamped in [ns] (``None`` while unknown).
        default_host: the box's address when ``settings.host`` is not set (the
            robot's: ``ffexp emulate`` serves both).
        where: how errors name that table (a rig file and table,
            ``"rigs/lwr4-lab.toml: ft"``); an error names ``<where>.<field>``.
    """

    def __init__(
        self, settings: NetFtConfig, clock: Callable[[], int | None] | None = None, *,
        default_host: str | None = None, where: str = "ft",
    ) -> None:
        self.settings = settings
        self.where = where
        host = settings.host if settings.host is not None else default_host
        if host is None:
            raise ConfigError(f"{where}.host", "", "required: the box's address")
        self.host = resolve_ipv4(f"{where}.host", host)
        self.addr = (self.host, int(settings.port))
        for name in ("counts_per_force", "counts_per_torque", "force_unit_n", "torque_unit_nm",
                     "sample_rate_hz"):
            value = getattr(settings, name)
            if not (np.isfinite(value) and value > 0):
                raise ConfigError(f"{where}.{name}", "", f"must be positive, got {value}")
        self._calibration = Calibration(settings.counts_per_force, settings.counts_per_torque,
                                        settings.force_unit_n, settings.torque_unit_nm)
        self.clock: Callable[[], int | None] = clock or time.monotonic_ns
        self._sock: socket.socket | None = None
        self._running = False
        self._buf = bytearray(MAX_RECORDS * 36 + 64)
        self._rec = RdtSamples.empty(MAX_RECORDS)
        self.decode_stats = RdtDecodeStats()
        self._period_ns = 1e9 / settings.sample_rate_hz
        self._last_rdt: int | None = None
        self._anchor: tuple[int, int] | None = None  # (unwrapped ft seq, time ns)
        self._ft_last: int | None = None
        self._ft_unwrapped = 0
        self._pending: list[NDArray[np.uint32]] = []
        self._datagrams = 0
        self._foreign = 0
        self._lost = 0
        self._duplicates = 0
        self._stale = 0
        self._reanchors = 0
        self._requests = 0
        self._last_request = 0.0
        self._last_rx = 0.0
        self._start_cmd = RdtCommand.START_REALTIME
        self._last_status = 0

    def open(self) -> tuple[str, int]:
        """Bind the local socket now (``start`` does it otherwise); returns its address."""
        if self._sock is None:
            s = self.settings
            self._sock = bind_udp(f"{self.where}.local_port", s.local_host, s.local_port)
            self._sock.setblocking(False)
        host, port = self._sock.getsockname()[:2]
        return str(host), int(port)

    def _request(self, command: RdtCommand) -> None:
        if self._sock is None:
            raise NotConnectedError(f"Net F/T {self.host}: not started")
        try:
            self._sock.sendto(encode_request(command), self.addr)
        except OSError as exc:
            raise NotConnectedError(
                f"Net F/T {self.host}:{self.addr[1]}: cannot send request: {exc}"
            ) from None

    def start(self) -> None:
        self.open()
        self._pending.clear()
        self._anchor = None
        self._last_rdt = None
        self._ft_last = None
        mode = RdtCommand.START_BUFFERED if self.settings.mode == "buffered" else (
            RdtCommand.START_REALTIME
        )
        self._start_cmd = mode
        self._last_rx = 0.0
        self._request(mode)
        self._requests += 1
        self._last_request = time.monotonic()
        self._running = True

    def stop(self) -> None:
        if self._sock is not None:
            if self._running:
                try:
                    self._sock.sendto(encode_request(RdtCommand.STOP), self.addr)
                except OSError:
                    pass
            self._sock.close()
            self._sock = None
        self._running = False

    @property
    def running(self) -> bool:
        return self._running

    @property
    def is_open(self) -> bool:
        return self._running and self._sock is not None

    @requires_open("Net F/T")
    def tare(self) -> None:
        """Ask the box for a software bias (0x0042)."""
        self._request(RdtCommand.SET_BIAS)

    def wait(self, timeout_s: float) -> bool:
        """Block until a datagram is waiting or ``timeout_s`` passed; True if one is."""
        if self._sock is None:
            return False
        r, _, _ = select.select([self._sock], [], [], max(timeout_s, 0.0))
        return bool(r)

    @property
    def stats(self) -> NetFtStats:
        return NetFtStats(
            datagrams=self._datagrams,
            foreign=self._foreign,
            decode=self.decode_stats.as_dict(),
            records=self.decode_stats.records,
            lost=self._lost,
            duplicates=self._duplicates,
            stale=self._stale,
            reanchors=self._reanchors,
            requests=self._requests,
            last_status=self._last_status,
        )

    def _drain(self) -> None:
        sock = self._sock
        assert sock is not None
        buf, view, rec = self._buf, memoryview(self._buf), self._rec
        while True:
            try:
                n, addr = sock.recvfrom_into(buf)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:  # ICMP port unreachable from an earlier request, etc.
                continue
            self._datagrams += 1
            if addr[0] != self.host or addr[1] != self.addr[1]:
                self._foreign += 1
                continue
            if decode_rdt_into(view[:n], rec, stats=self.decode_stats) is not RdtDecodeStatus.OK:
                continue
            seq = int(rec.rdt_seq[0])
            if self._last_rdt is not None:
                d = rdt_seq_delta(seq, self._last_rdt)
                if d == 0:
                    self._duplicates += 1
                    continue
                if d < 0:
                    self._stale += 1
                    continue
                self._lost += d - 1
            self._last_rdt = seq
            self._last_rx = time.monotonic()
            self._pending.append(rec.words[: rec.n].copy())

    @requires_open("Net F/T")
    def samples(self) -> FtSamples:
        self._drain()
        now = time.monotonic()
        resend = self.settings.resend_s
        if now - max(self._last_rx, self._last_request) > resend:
            # the box was not up yet, or it stopped; best effort (the runner's
            # stale-data watchdog decides when silence is too long)
            with contextlib.suppress(NotConnectedError):
                self._request(self._start_cmd)
            self._requests += 1
            self._last_request = now
        if not self._pending:
            return FtSamples()
        words = np.concatenate(self._pending) if len(self._pending) > 1 else self._pending[0]
        self._pending = []
        recs = RdtSamples(words, words.shape[0])
        wrench = counts_to_si(recs.counts, self._calibration)
        status = recs.status.copy()
        self._last_status = int(status[-1])
        # unwrap ft_sequence (uint32) into a running count
        ft = recs.ft_seq.astype(np.int64)
        seq = np.empty(ft.shape[0], dtype=np.int64)
        prev, acc = self._ft_last, self._ft_unwrapped
        for i, v in enumerate(ft.tolist()):
            if prev is not None:
                acc += rdt_seq_delta(v, prev)
            else:
                acc = v
            prev = v
            seq[i] = acc
        self._ft_last, self._ft_unwrapped = prev, acc
        times = self._stamp(seq)
        return FtSamples(time_ns=times, seq=seq, wrench=wrench, status=status)

    def _stamp(self, seq: NDArray[np.int64]) -> NDArray[np.int64]:
        now = self.clock()
        last = int(seq[-1])
        if self._anchor is not None and now is not None:
            t_last = self._anchor[1] + (last - self._anchor[0]) * self._period_ns
            if abs(t_last - now) > self.settings.reanchor_s * 1e9:
                self._anchor = None
                self._reanchors += 1
        if self._anchor is None:
            if now is None:
                now = time.monotonic_ns()
            self._anchor = (last, int(now))
        s0, t0 = self._anchor
        return (t0 + np.round((seq - s0) * self._period_ns)).astype(np.int64)
