"""The KRC2 LR as :class:`~drivers.emulate.session.EmulatedRig` serves it (``--robot lwr4``).

:func:`serve` is the family's :class:`~drivers.base.backend.Emulator` ``serve``: it builds
the :class:`~drivers.fri.emulate.server.FriEmulator` that sends FRI datagrams to the
remote driver and runs it in a thread of its own (started by :meth:`ServedKrc.serve`: it
inherits the caller's scheduling), until the duration, a stop request or an error, which
is re-raised in the caller's thread.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from drivers.emulate.netft_box import NetFtServer
from drivers.emulate.session import EmulatedRigSettings
from drivers.errors import ConfigError
from drivers.fri.emulate.server import EmulatorSettings, EmulatorStats, FriEmulator
from drivers.world.world import SimWorld

__all__ = ["STATUS_PERIOD_S", "ServedKrc", "serve"]

#: How often the KRC's status line comes [s of wall time].
STATUS_PERIOD_S = 5.0
#: How often the serving caller checks for a stop request [s].
_POLL_S = 0.1


class ServedKrc:
    """The KRC over FRI on the rig's world (:class:`~drivers.emulate.served.ServedRobot`)."""

    def __init__(self, emulator: FriEmulator, settings: EmulatedRigSettings) -> None:
        self.emulator = emulator
        self.settings = settings
        self._thread: threading.Thread | None = None
        self._failure: BaseException | None = None
        self._stats: EmulatorStats | None = None

    @property
    def address(self) -> tuple[str, int]:
        return self.emulator.address

    def ready_line(self) -> str:
        host, port = self.emulator.address
        r = self.settings.remote
        remote = "?" if r is None else f"{r[0]}:{r[1]}"
        return f"KRC on {host}:{port} -> remote {remote}"

    def serve(self, stop_requested: Callable[[], bool], on_status: Callable[[str], None] | None,
              on_cycle: Callable[[], None], max_cycles: int | None,
              duration_s: float) -> EmulatorStats:
        robot = self.emulator
        last_status = time.monotonic()

        def each_cycle(emu: FriEmulator) -> None:
            nonlocal last_status
            on_cycle()
            now = time.monotonic()
            if on_status is not None and now - last_status >= STATUS_PERIOD_S:
                last_status = now
                st = emu.stats
                on_status(f"t={emu.world.time:7.2f} s  {emu.state.name} {emu.quality.name}  "
                          f"answered {st.answered} missed {st.missed} applied {st.applied}")

        def run() -> None:
            try:
                robot.run(max_cycles=max_cycles, on_cycle=each_cycle)
            except BaseException as exc:  # re-raised below, in the caller's thread
                self._failure = exc

        self._thread = thread = threading.Thread(target=run, name="fri-emulator", daemon=True)
        thread.start()
        # lockstep steps the world on answers: with no remote answering, no simulated time
        # passes, so the duration also ends the wait for a first answer after as much wall time
        alone_until = time.monotonic() + duration_s if duration_s > 0 else None
        while thread.is_alive():
            if stop_requested() or (alone_until is not None and robot.stats.answered == 0
                                    and time.monotonic() >= alone_until):
                robot.stop()
            thread.join(_POLL_S)
        if self._failure is not None:
            raise self._failure
        return robot.stats

    def stop(self) -> None:
        self.emulator.stop()

    def close(self) -> None:
        robot = self.emulator
        robot.stop()
        if self._thread is not None and self._thread.is_alive():
            self._thread.join(5.0)
        robot.close()  # closes the Net F/T box too
        self._stats = robot.stats

    def summary(self) -> str:
        stats = self._stats if self._stats is not None else self.emulator.stats
        stats.state, stats.quality = self.emulator.state, self.emulator.quality
        return stats.summary()


def serve(world: SimWorld, settings: EmulatedRigSettings,
          ft_box: NetFtServer | None) -> ServedKrc:
    """The KRC2 LR sending to ``settings.remote`` (required), with the Net F/T box."""
    s = settings
    if s.remote is None:
        raise ConfigError(s.fields.remote, "", "the remote driver's address is required")
    emulator = FriEmulator(
        world,
        EmulatorSettings(remote=s.remote, port=s.port, port_field=s.fields.port,
                         bind_host=s.host, pacing=s.pacing,
                         lockstep_timeout_s=s.lockstep_timeout_s, faults=s.faults),
        ft_box,
    )
    return ServedKrc(emulator, settings)
