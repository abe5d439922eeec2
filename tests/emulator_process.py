"""``ffexp emulate`` as a child process in tests: a free port, and a stop that never hangs."""

from __future__ import annotations

import signal
import socket
import subprocess


def free_udp_port() -> int:
    """A port that was free a moment ago (the two processes need to know each other's)."""
    return free_udp_ports(1)[0]


def free_udp_ports(n: int) -> list[int]:
    """``n`` different ports that were free a moment ago: all bound at once, so that two
    calls in a row cannot hand out the same port twice."""
    socks = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(n)]
    try:
        for s in socks:
            s.bind(("127.0.0.1", 0))
        return [int(s.getsockname()[1]) for s in socks]
    finally:
        for s in socks:
            s.close()


def stop_emulator(emulator: subprocess.Popen[str], timeout_s: float = 30.0) -> str:
    """SIGTERM (the emulator's clean stop), killed if it has not ended in ``timeout_s``;
    its stderr."""
    emulator.send_signal(signal.SIGTERM)
    try:
        _out, err = emulator.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        emulator.kill()
        _out, err = emulator.communicate()
    return err
