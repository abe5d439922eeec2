"""Network plumbing shared by the device back-ends (FRI, Net F/T, ...): addresses and sockets.

No back-end specific code lives here; back-ends import this package, never each other.
"""

from drivers.net.udp import bind_udp, parse_host, parse_host_port, parse_port, resolve_ipv4

__all__ = ["bind_udp", "parse_host", "parse_host_port", "parse_port", "resolve_ipv4"]
