"""The Net F/T back-end's rig table: the ``netft`` F/T source.

Each model is what the back-end's device takes as it is (no second settings class);
its fields are spelled as the rig file spells them. Light: pydantic only.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from drivers.base.backend import DeviceConfig
from drivers.config import PosFloat

__all__ = ["NetFtConfig"]


class NetFtConfig(DeviceConfig):
    """An ATI Net F/T box (RDT over UDP): where it is, how it scales, how it is asked."""

    type: Literal["netft"] = "netft"
    host: str | None = None
    """The box's address; default: the robot's address (``ffexp emulate`` serves both)."""
    port: Annotated[int, Field(ge=1, le=65535)] = 49152
    """Its RDT port."""
    counts_per_force: PosFloat = 1_000_000.0
    """Counts per force unit (``cfgcpf`` in the box's netftapi2.xml)."""
    counts_per_torque: PosFloat = 1_000_000.0
    """Counts per torque unit (``cfgcpt``)."""
    force_unit_n: PosFloat = 1.0
    """Newtons per force unit of the box (1.0 for N; ``scfgfu``)."""
    torque_unit_nm: PosFloat = 1.0
    """Newton metres per torque unit (1.0 for N m, 0.001 for N mm; ``scfgtu``)."""
    sample_rate_hz: PosFloat = 1000.0
    """The box's internal sample rate (the ``ft_sequence`` step)."""
    mode: Literal["realtime", "buffered"] = "realtime"
    """``realtime`` (0x0002) or ``buffered`` (0x0003)."""
    local_host: str = "0.0.0.0"
    """Local address to bind."""
    local_port: Annotated[int, Field(ge=0, le=65535)] = 0
    """Local UDP port (0: any free port)."""
    reanchor_s: PosFloat = 0.1
    """Re-anchor the time stamps when they drift this far from the clock."""
    resend_s: PosFloat = 0.05
    """Repeat the start request while nothing has come for this long."""
