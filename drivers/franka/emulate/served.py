"""The FR3 as :class:`~drivers.emulate.session.EmulatedRig` serves it (``--robot fr3``):
:func:`serve`, the family's :class:`~drivers.base.backend.Emulator` ``serve``.

The server listens on ``settings.listen`` (default 127.0.0.1:1337) from the start (a
client that connects early waits in the listen queue) and serves in a thread of its own
that :meth:`ServedFr3.serve` starts and waits for: started there, inside ``ffexp emulate
--rt``'s real-time settings, the thread takes them (on Linux a thread's scheduling policy
and CPU affinity are its own, set at its creation from its creator's: a thread started
before ``--rt`` would stay at normal priority on every CPU). The family's faults (``--fault
NAME=VALUE``): ``silence=1``, ``version=N``, ``drop_after=MS``, ``reflex_after=MS``
(:class:`~drivers.franka.emulate.server.FciFaults`).
"""

from __future__ import annotations

import time
from collections.abc import Callable

from drivers.emulate.netft_box import NetFtServer
from drivers.emulate.session import EmulatedRigSettings
from drivers.errors import ConfigError
from drivers.franka.backend import EMULATOR
from drivers.franka.emulate.server import FciFaults, FciServer
from drivers.world.world import SimWorld

__all__ = ["STATUS_PERIOD_S", "ServedFr3", "serve"]

#: How often the controller's status line comes [s of wall time].
STATUS_PERIOD_S = 5.0
_POLL_S = 0.05


class ServedFr3:
    """The FR3 over libfranka's protocol (:class:`~drivers.emulate.served.ServedRobot`)."""

    def __init__(self, server: FciServer) -> None:
        self.server = server
        self._stop = False

    @property
    def address(self) -> tuple[str, int]:
        return self.server.address

    def ready_line(self) -> str:
        host, port = self.server.address
        return f"FR3 (libfranka protocol v{self.server.faults.version}) on {host}:{port}"

    def serve(self, stop_requested: Callable[[], bool], on_status: Callable[[str], None] | None,
              on_cycle: Callable[[], None], max_cycles: int | None, duration_s: float) -> None:
        srv = self.server
        if not srv.started:
            srv.start()
        last = time.monotonic()
        end = time.monotonic() + duration_s if duration_s > 0 else None
        while not self._stop and not stop_requested():
            if srv.error is not None:
                raise srv.error
            if max_cycles is not None and srv.steps >= max_cycles:
                break
            if end is not None and srv.steps == 0 and time.monotonic() >= end:
                break  # nobody drove the arm: as much wall time as the duration
            now = time.monotonic()
            if on_status is not None and now - last >= STATUS_PERIOD_S:
                last = now
                # the counters only: the cycles' CPU percentiles (a partition of up to
                # 65,536 values) would hold the interpreter lock from the serving thread
                on_status(f"t={srv.world.time:7.2f} s  {srv.summary(cost=False)}")
            time.sleep(_POLL_S)
        srv.stop()
        if srv.error is not None:
            raise srv.error

    def stop(self) -> None:
        self._stop = True

    def close(self) -> None:
        self.server.close()

    def summary(self) -> str:
        return f"FR3 over libfranka's protocol: {self.server.steps} cycles; {self.server.summary()}"


def _count(settings: EmulatedRigSettings, name: str) -> int:
    value = settings.family_faults.get(name, 0)
    if value < 0 or value != int(value):
        raise ConfigError(settings.fields.fault, f"{name}={value:g}", "a whole number >= 0")
    return int(value)


def serve(world: SimWorld, settings: EmulatedRigSettings,
          ft_box: NetFtServer | None) -> ServedFr3:
    """The FR3 listening on ``settings.listen`` (its wrench goes over its own link)."""
    s = settings
    if s.remote is not None:
        raise ConfigError(s.fields.remote, f"{s.remote[0]}:{s.remote[1]}", "the fr3 emulator "
                          "sends to no remote driver: its client connects to it (--listen)")
    version = _count(s, "version") if "version" in s.family_faults else None
    faults = FciFaults(silence=bool(_count(s, "silence")),
                       drop_after=_count(s, "drop_after"), reflex_after=_count(s, "reflex_after"),
                       **({"version": version} if version is not None else {}))
    host, port = s.listen or EMULATOR.listen or ("127.0.0.1", 1337)
    server = FciServer(world, host, port, pacing=s.pacing,
                       lockstep_timeout_s=s.lockstep_timeout_s, faults=faults,
                       where=s.fields.listen)
    return ServedFr3(server)
