"""The FRI back-end's rig tables: the ``fri1`` robot and the ``fri-estimate`` F/T source.

Each model is what the back-end's device takes as it is (no second settings class);
its fields are spelled as the rig file spells them. Light: pydantic only.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, ClassVar, Literal

from pydantic import Field

from drivers.base.backend import DeviceConfig
from drivers.config import Port, PosFloat

__all__ = ["FriEstimateFt", "FriRobotConfig", "SimRobotConfig"]


class FriRobotConfig(DeviceConfig):
    """A KUKA KRC2 LR over FRI 1.x (UDP): where the KRC is and how to answer it."""

    type: Literal["fri1"] = "fri1"
    offers: ClassVar[frozenset[str]] = frozenset({"netft-host"})  # the box beside the KRC
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


class SimRobotConfig(DeviceConfig):
    """The simulated LWR4+ in-process (lockstep, no sockets)."""

    type: Literal["sim"] = "sim"
    #: it runs the world in-process and leaves the world's F/T samples to the sim sensor
    offers: ClassVar[frozenset[str]] = frozenset({"world", "world-ft"})
    start_cycles: Annotated[int, Field(ge=0)] = 100
    """Answered cycles before the link enters command mode (a friStart script: 100)."""
    max_consecutive_misses: Annotated[int, Field(ge=1)] = 5
    """Cycles without an answer in a row that end command mode."""
    scene_file: Path | None = None
    """Scene TOML (relative to the rig file); default: the protocol's scene."""
    wire_precision: bool = False
    """Round the measurement and the command through the FRI codec, as the UDP link
    does: with ``ft.type = "fri-estimate"`` a run equals the same run in lockstep
    over UDP against ``ffexp emulate``, bit for bit."""
