"""The Net F/T back-end's entry: the ``netft`` F/T source (an ATI Net F/T box, RDT over UDP).

:class:`NetFtConfig` (:mod:`drivers.netft.config`) is the rig's ``[ft]`` table and what
:class:`~drivers.netft.client.NetFtClient` takes; its errors name the rig's
fields. Light: the client is imported when a rig opens it.
"""

from __future__ import annotations

from drivers.base.backend import (
    Backend,
    DeviceConfig,
    FtBackend,
    OpenContext,
    OpenedRobot,
    OpenedSensor,
    offering,
)
from drivers.netft.config import NetFtConfig

__all__ = ["BACKEND", "NetFtConfig"]


def _open_ft(cfg: NetFtConfig, ctx: OpenContext, robot: OpenedRobot) -> OpenedSensor:
    from drivers.netft.client import NetFtClient

    client = NetFtClient(cfg, clock=robot.clock, default_host=robot.host, where=ctx.where("ft"))
    client.open()
    addr = f"{client.addr[0]}:{client.addr[1]}"
    return OpenedSensor(client, {"netft": addr}, f"Net F/T at {addr}")


def _check_ft(cfg: NetFtConfig, robot: DeviceConfig) -> str | None:
    if cfg.host is not None or "netft-host" in type(robot).offers:
        return None
    beside = " or ".join(f"'{t}'" for t in offering("netft-host"))
    return f"ft.host is required unless robot.type is {beside}"


BACKEND = Backend("netft", sensors=(FtBackend(NetFtConfig, _open_ft, _check_ft),))
