"""The FRI back-end's rig tables: the ``fri1`` robot and the ``fri-estimate`` F/T source.

Each model is what the back-end's device takes as it is (no second settings class);
its fields are spelled as the rig file spells them. Light: pydantic only.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from drivers.base.backend import DeviceConfig
from drivers.config import Port, PosFloat

__all__ = ["FriEstimateFt", "FriRobotConfig"]


class FriRobotConfig(DeviceConfig):
    """A KUKA KRC2 LR over FRI 1.x (UDP): where the KRC is and how to answer it."""

    type: Literal["fri1"] = "fri1"
    robot_ip: str
    """The KRC's address (IPv4 or host name); packets from anywhere else are dropped."""
    port: Port = 49938
    """Local UDP port (``FRISOCK`` in the KRC's dlrrc.ini; 0 = any free port)."""
    bind_host: str = "0.0.0.0"
    """Local address to bind."""
    robot_port: Annotated[int, Field(ge=1, le=65535)] | None = None
    """If set, also require this source port."""
    answer_deadline_cycles: Annotated[float, Field(ge=0.0)] = 0.5
    """Latest answer, in cycles after the packet arrived; 0 answers on arrival."""
    follow_lockstep_marker: bool = True
    """Wait for the runner when the emulator says lockstep."""
    connect_timeout_s: PosFloat = 10.0
    """Longest wait for the first measurement."""
    cycle_timeout_s: PosFloat = 1.0
    """Longest gap between measurements before the link is lost."""
    runner_timeout_s: PosFloat = 5.0
    """In lockstep, longest wait for the runner's command."""
    poll_s: PosFloat = 0.05
    """How often the I/O thread wakes up to notice ``close()``."""
    restart_seq_jump: Annotated[int, Field(ge=1)] = 100
    """A measurement older than this many cycles is a KRC restart, not reordering."""
    min_cycle_s: PosFloat = 0.0009
    """Shortest plausible cycle (friOpen takes 1..100 ms); shorter packets are dropped."""
    max_cycle_s: PosFloat = 0.101
    """Longest plausible cycle."""


class FriEstimateFt(DeviceConfig):
    """The KRC's own estimate of the external wrench (``estExtTcpFT``), one sample per cycle."""

    type: Literal["fri-estimate"] = "fri-estimate"
