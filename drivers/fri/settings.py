"""Settings of the FRI remote driver: every number of the link a user may need to change.

A plain dataclass with defaults (the rig-file factory fills it); units in the
names. :attr:`FriSettings.source` names where the values came from, so that an
address error reads ``"rigs/lwr4-lab.toml: robot.robot_ip: 10.0.0: not a valid ..."``.
"""

from __future__ import annotations

from dataclasses import dataclass

from drivers.fri.codec_layout import DEFAULT_PORT

__all__ = ["DEFAULT_PORT", "FriSettings"]


@dataclass(frozen=True)
class FriSettings:
    """Where the KRC is and how to answer it.

    Args:
        robot_ip: the KRC's address (IPv4 or host name); packets from anywhere
            else are dropped.
        local_port: local UDP port (``FRISOCK`` in the KRC's dlrrc.ini; 0 = any free port).
        local_host: local address to bind (default all interfaces).
        robot_port: if set, also require this source port.
        answer_deadline_cycles: latest answer, in cycles after the packet
            arrived; 0 answers on arrival with the latest command.
        follow_lockstep_marker: wait for the runner when the emulator says lockstep.
        connect_timeout_s: longest wait for the first measurement.
        cycle_timeout_s: longest gap between measurements before the link is lost.
        runner_timeout_s: in lockstep, longest wait for the runner's command.
        poll_s: how often the I/O thread wakes up to notice ``close()``.
        restart_seq_jump: a measurement older than this many cycles is taken
            as a KRC restart, not as reordering.
        min_cycle_s, max_cycle_s: plausible ``desiredMsrSampleTime`` (friOpen
            takes 1..100 ms); packets outside are dropped as implausible.
        source: where these settings came from (a rig file and table, e.g.
            ``"rigs/lwr4-lab.toml: robot"``); error messages name ``<source>.<field>``.
    """

    robot_ip: str
    local_port: int = DEFAULT_PORT
    local_host: str = "0.0.0.0"
    robot_port: int | None = None
    answer_deadline_cycles: float = 0.5
    follow_lockstep_marker: bool = True
    connect_timeout_s: float = 10.0
    cycle_timeout_s: float = 1.0
    runner_timeout_s: float = 5.0
    poll_s: float = 0.05
    restart_seq_jump: int = 100
    min_cycle_s: float = 0.0009
    max_cycle_s: float = 0.101
    source: str = "FriSettings"

    def where(self, field: str) -> str:
        """``"<source>.<field>"``: how an error names one of these settings."""
        return f"{self.source}.{field}"
