"""UDP addresses and sockets for the back-ends that speak UDP (FRI, Net F/T).

Every failure a user can cause (a malformed or unresolvable address, a port
out of range or in use, an address that is not local) becomes one
:class:`~drivers.errors.AddressError` line. Each function takes ``field``:
the caller's name for where the address came from (a rig file and field such
as ``"rigs/lwr4-lab.toml: robot.robot_ip"``, or a rig table's field such as
``"robot.robot_ip"``); the message starts with it. Nothing here knows
command-line flags.
"""

from __future__ import annotations

import ipaddress
import socket
import struct
import sys
from collections.abc import Iterable
from typing import Final

from drivers.errors import AddressError

__all__ = [
    "RCVBUF_BYTES",
    "bind_udp",
    "enable_kernel_stamps",
    "kernel_stamp_ns",
    "parse_host",
    "parse_host_port",
    "parse_port",
    "resolve_ipv4",
]

#: Receive buffer asked for on every socket (the kernel may grant less).
RCVBUF_BYTES: Final = 1 << 20


def resolve_ipv4(field: str, host: str) -> str:
    """``host`` (a dotted IPv4 address or a name) as a dotted IPv4 address.

    Raises:
        AddressError: empty, malformed, or the name does not resolve.
    """
    text = host.strip()
    if not text:
        raise AddressError(field, repr(host), "empty address")
    try:
        return str(ipaddress.IPv4Address(text))
    except ValueError:
        pass
    if all(c.isdigit() or c == "." for c in text):
        raise AddressError(field, host, "not a valid IPv4 address (expected a.b.c.d)")
    if any(c in text for c in " /\\:@"):
        raise AddressError(field, host, "not an IPv4 address or host name")
    try:
        infos = socket.getaddrinfo(text, None, socket.AF_INET, socket.SOCK_DGRAM)
    except (socket.gaierror, UnicodeError) as exc:
        raise AddressError(field, host, f"cannot resolve host name ({exc})") from None
    return str(infos[0][4][0])


def parse_host(field: str, text: str) -> str:
    """An IPv4 address or host name, resolved (same as :func:`resolve_ipv4`)."""
    return resolve_ipv4(field, text)


def parse_port(field: str, text: str, port: str | int, *, allow_zero: bool) -> int:
    """A UDP port number; 0 (any free port) only where ``allow_zero``.

    ``text`` is the address as the user gave it (shown in the message).
    """
    try:
        value = int(port)
    except (TypeError, ValueError):
        raise AddressError(field, text, f"port {port!r} is not a number") from None
    low = 0 if allow_zero else 1
    if not low <= value <= 65535:
        raise AddressError(field, text, f"port {value} is outside {low}..65535")
    return value


def parse_host_port(field: str, text: str, default_port: int | None = None) -> tuple[str, int]:
    """``HOST:PORT`` (or ``HOST`` when ``default_port`` is given) -> ``(ipv4, port)``."""
    host, sep, port = text.strip().rpartition(":")
    if not sep:
        if default_port is None:
            raise AddressError(field, text, "expected HOST:PORT")
        host, port = text.strip(), str(default_port)
    return resolve_ipv4(field, host), parse_port(field, text, port, allow_zero=False)


def bind_udp(field: str, host: str, port: int) -> socket.socket:
    """A UDP socket bound to ``host:port`` (port 0: any free port), with a large receive buffer.

    Raises:
        AddressError: the port is out of range or in use, the address is not
            local, or the port is privileged.
    """
    parse_port(field, f"{host}:{port}", port, allow_zero=True)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RCVBUF_BYTES)
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        where = f"{host or '0.0.0.0'}:{port}"
        reason = exc.strerror or str(exc)
        raise AddressError(field, where, f"cannot bind UDP socket: {reason}") from None
    return sock


#: Linux's SO_TIMESTAMPNS (asm-generic value; Python's socket module does not name
#: it): the kernel stamps each datagram with its arrival time (CLOCK_REALTIME).
_SO_TIMESTAMPNS: Final = 35
_TIMESPEC = struct.Struct("@qq")


def enable_kernel_stamps(sock: socket.socket) -> bool:
    """Ask the kernel to stamp arriving datagrams; False where it cannot. With it,
    read with ``sock.recvmsg_into(buffers, 64)`` and :func:`kernel_stamp_ns`."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        sock.setsockopt(socket.SOL_SOCKET, _SO_TIMESTAMPNS, 1)
    except OSError:
        return False
    return True


def kernel_stamp_ns(ancdata: Iterable[tuple[int, int, bytes]]) -> int:
    """The kernel's arrival stamp [ns since the epoch] in a datagram's ancillary data
    (``recvmsg``), 0 when it has none."""
    for level, kind, data in ancdata:
        if level == socket.SOL_SOCKET and kind == _SO_TIMESTAMPNS:
            sec, nsec = _TIMESPEC.unpack_from(data)
            return int(sec * 1_000_000_000 + nsec)
    return 0
