"""The UR controller as :class:`~drivers.emulate.session.EmulatedRig` serves it (``--robot
ur5e``): :func:`serve`, the family's :class:`~drivers.base.backend.Emulator` ``serve``.

The RTDE server listens on ``settings.listen`` (default 127.0.0.1:30004) as the rig opens
and serves in its own thread, started by :meth:`ServedUr.serve` (so under ``ffexp emulate
--rt`` it takes the real-time policy and the pinned CPU), which waits for it. Faults:
``faults.loss`` and ``faults.delay_s`` of the output packages, and the family's
``disconnect_after``
(:class:`~drivers.ur.emulate.rtde_server.RtdeFaults`).
"""

from __future__ import annotations

import time
from collections.abc import Callable

from drivers.emulate.netft_box import NetFtServer
from drivers.emulate.session import EmulatedRigSettings
from drivers.errors import ConfigError
from drivers.ur.backend import EMULATOR
from drivers.ur.emulate.rtde_server import RtdeFaults
from drivers.ur.emulate.server import UrEmulator
from drivers.world.world import SimWorld

__all__ = ["STATUS_PERIOD_S", "ServedUr", "serve"]

#: How often the controller's status line comes [s of wall time].
STATUS_PERIOD_S = 5.0


class ServedUr:
    """The UR controller over RTDE (:class:`~drivers.emulate.served.ServedRobot`)."""

    def __init__(self, emulator: UrEmulator) -> None:
        self.emulator = emulator

    @property
    def address(self) -> tuple[str, int]:
        return self.emulator.address

    def ready_line(self) -> str:
        host, port = self.emulator.address
        return f"UR5e controller (RTDE) on {host}:{port}"

    def serve(self, stop_requested: Callable[[], bool], on_status: Callable[[str], None] | None,
              on_cycle: Callable[[], None], max_cycles: int | None, duration_s: float) -> None:
        last_status = time.monotonic()

        def each_poll(emu: UrEmulator) -> None:
            nonlocal last_status
            if stop_requested():
                emu.stop()
            now = time.monotonic()
            if on_status is not None and now - last_status >= STATUS_PERIOD_S:
                last_status = now
                on_status(emu.status())

        # the duration also bounds the wall time without a client: then the world never steps
        self.emulator.run(max_cycles=max_cycles, on_cycle=each_poll,
                          max_wall_s=duration_s if duration_s > 0 else None)

    def stop(self) -> None:
        self.emulator.stop()

    def close(self) -> None:
        self.emulator.close()

    def summary(self) -> str:
        return self.emulator.summary()


def serve(world: SimWorld, settings: EmulatedRigSettings,
          ft_box: NetFtServer | None) -> ServedUr:
    """The UR controller listening on ``settings.listen`` (its wrench goes over RTDE)."""
    s = settings
    if s.remote is not None:
        raise ConfigError(s.fields.remote, f"{s.remote[0]}:{s.remote[1]}", "the ur5e emulator "
                          "sends to no remote driver: its client connects to it (--listen)")
    after = s.family_faults.get("disconnect_after", 0)
    if after < 0 or after != int(after):
        raise ConfigError(s.fields.fault, f"disconnect_after={after:g}",
                          "a count of data packages, >= 0")
    faults = RtdeFaults(loss=s.faults.loss, delay_s=s.faults.delay_s,
                        disconnect_after=int(after), seed=s.faults.seed)
    host, port = s.listen or EMULATOR.listen or ("127.0.0.1", 30004)
    emulator = UrEmulator(world, host, port, pacing=s.pacing,
                          lockstep_timeout_s=s.lockstep_timeout_s, faults=faults,
                          where=s.fields.listen).start(thread=False)
    return ServedUr(emulator)
