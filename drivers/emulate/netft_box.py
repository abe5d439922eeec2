"""An emulated ATI Net F/T box: answers RDT requests and streams given samples.

The owner (the FRI emulator of ``ffexp emulate``) calls :meth:`NetFtServer.handle_requests` when
the socket is readable and :meth:`NetFtServer.publish` with the samples its
sensor model produced each FRI cycle; there is no thread of its own.

Behaviour, as a Net F/T box: a request from any address takes over the
stream (one client at a time); ``0x0002`` streams one record per datagram,
``0x0003`` packs up to ``buffer_size`` records per datagram, ``sample_count``
> 0 stops after that many records, ``0x0000`` stops, ``0x0042`` (software
bias) calls ``on_bias``, ``0x0041`` (reset latch) is accepted. Bad requests
are counted and ignored. ``rdt_sequence`` counts datagrams, ``ft_sequence``
is the sensor's sample counter. Status words get the error-summary bit
0x80000000 whenever any other bit is set, as on the box.
"""

from __future__ import annotations

import socket
from collections.abc import Callable

import numpy as np

from drivers.base.types import FtSamples
from drivers.errors import MalformedPacketError
from drivers.net.udp import bind_udp
from drivers.netft.codec import (
    MAX_RECORDS,
    Calibration,
    RdtCommand,
    decode_request,
    encode_rdt,
    si_to_counts,
)

__all__ = ["NetFtServer"]

_SUMMARY = np.uint32(0x80000000)


class NetFtServer:
    """The box side of RDT over UDP.

    Args:
        sock: a bound UDP socket (see :meth:`open`).
        calibration: counts per unit and units the box reports in.
        buffer_size: records per datagram in buffered mode (1..40).
        on_bias: called for a software-bias request.
    """

    def __init__(
        self,
        sock: socket.socket,
        calibration: Calibration | None = None,
        buffer_size: int = 10,
        on_bias: Callable[[], None] | None = None,
    ) -> None:
        if not 1 <= buffer_size <= MAX_RECORDS:
            raise ValueError(f"buffer_size must be 1..{MAX_RECORDS}, got {buffer_size}")
        self.sock = sock
        sock.setblocking(False)
        self.calibration = calibration if calibration is not None else Calibration()
        self.buffer_size = buffer_size
        self.on_bias = on_bias
        self.client: tuple[str, int] | None = None
        self.buffered = False
        self.remaining: int | None = None
        self.rdt_seq = 0
        self.requests = 0
        self.bad_requests = 0
        self.datagrams = 0
        self.records = 0
        self._buf = bytearray(2048)

    @classmethod
    def open(
        cls,
        host: str = "0.0.0.0",
        port: int = 0,
        calibration: Calibration | None = None,
        buffer_size: int = 10,
        on_bias: Callable[[], None] | None = None,
        field: str = "Net F/T box port",
    ) -> NetFtServer:
        """Bind ``host:port`` (0: any free port) and serve there.

        ``field`` names the port's origin in an :class:`~drivers.errors.AddressError`.
        """
        return cls(bind_udp(field, host, port), calibration, buffer_size, on_bias)

    @property
    def address(self) -> tuple[str, int]:
        host, port = self.sock.getsockname()[:2]
        return str(host), int(port)

    def fileno(self) -> int:
        return self.sock.fileno()

    def close(self) -> None:
        self.sock.close()

    def handle_requests(self) -> None:
        """Read every pending request (non-blocking)."""
        while True:
            try:
                n, addr = self.sock.recvfrom_into(self._buf)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                return
            try:
                req = decode_request(memoryview(self._buf)[:n], source=addr)
            except MalformedPacketError:
                self.bad_requests += 1
                continue
            self.requests += 1
            cmd = req.command
            if cmd in (RdtCommand.START_REALTIME, RdtCommand.START_BUFFERED):
                self.client = (str(addr[0]), int(addr[1]))
                self.buffered = cmd == RdtCommand.START_BUFFERED
                self.remaining = req.sample_count or None
            elif cmd == RdtCommand.STOP:
                self.client = None
            elif cmd == RdtCommand.SET_BIAS:
                if self.on_bias is not None:
                    self.on_bias()
            elif cmd == RdtCommand.MULTI_UNIT:
                self.bad_requests += 1  # not emulated

    def publish(self, samples: FtSamples) -> int:
        """Stream ``samples`` to the client, if any; returns the records sent."""
        client = self.client
        n = len(samples)
        if client is None or n == 0:
            return 0
        if self.remaining is not None:
            n = min(n, self.remaining)
        counts = si_to_counts(samples.wrench[:n], self.calibration)
        status = samples.status[:n].astype(np.uint32)
        status = np.where(status != 0, status | _SUMMARY, status).astype(np.uint32)
        ft_seq = samples.seq[:n]
        step = self.buffer_size if self.buffered else 1
        sent = 0
        for a in range(0, n, step):
            b = min(a + step, n)
            data = encode_rdt(self.rdt_seq, ft_seq[a:b], status[a:b], counts[a:b])
            try:
                self.sock.sendto(data, client)
            except OSError:
                pass  # the client's port is gone (ICMP); a real box keeps streaming
            self.rdt_seq = (self.rdt_seq + 1) & 0xFFFFFFFF
            self.datagrams += 1
            sent += b - a
        self.records += sent
        if self.remaining is not None:
            self.remaining -= sent
            if self.remaining <= 0:
                self.client = None
                self.remaining = None
        return sent
