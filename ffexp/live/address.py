"""The live server's address and rate, as ``ffexp run --live [HOST:PORT]`` gives them."""

from __future__ import annotations

from dataclasses import dataclass

from drivers.errors import AddressError

#: ``--live`` without a value: loopback only (a viewer on this machine), Foxglove's port.
DEFAULT_ADDRESS = "127.0.0.1:8765"
#: Messages per second and topic a viewer gets of every high-rate topic.
DEFAULT_RATE_HZ = 50.0


@dataclass(frozen=True)
class LiveOptions:
    """Where the live server listens (``port`` 0: any free port) and how often it
    publishes each high-rate topic; ``where`` names the option in errors."""

    host: str = "127.0.0.1"
    port: int = 8765
    rate_hz: float = DEFAULT_RATE_HZ
    where: str = "--live"

    @property
    def address(self) -> str:
        return f"{self.host}:{self.port}"


def parse_address(text: str, where: str = "--live") -> LiveOptions:
    """``HOST:PORT``, ``HOST`` or ``:PORT`` (the rest from :data:`DEFAULT_ADDRESS`);
    IPv6 hosts in brackets (``[::1]:8765``). A bad one is an :class:`AddressError`
    naming ``where``."""
    default_host, _, default_port = DEFAULT_ADDRESS.rpartition(":")
    text = text.strip()
    if text.startswith("["):
        host, sep, rest = text[1:].partition("]")
        if not sep or (rest and not rest.startswith(":")):
            raise AddressError(where, text, "expected [IPV6]:PORT")
        port_text = rest[1:]
    elif text.count(":") == 1:
        host, _, port_text = text.partition(":")
    elif ":" in text:
        raise AddressError(where, text, "put an IPv6 host in brackets: [::1]:8765")
    else:
        host, port_text = text, ""
    host = host or default_host
    port_text = port_text or default_port
    try:
        port = int(port_text)
    except ValueError:
        raise AddressError(where, text, f"port {port_text!r} is not a number") from None
    if not 0 <= port <= 65535:
        raise AddressError(where, text, f"port {port} is outside 0..65535")
    return LiveOptions(host=host, port=port, where=where)
