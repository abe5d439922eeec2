"""The emulated UR5e over RTDE: the simulated world behind a UR controller's port 30004.

:class:`UrEmulator` serves :class:`~drivers.ur.emulate.controller.UrSimController`
(ffexp's URScript program on the world) with
:class:`~drivers.ur.emulate.rtde_server.RtdeServer`: every base cycle (the scene's
``fri.cycle``, 2 ms: 500 Hz) the server's thread runs the world one cycle with
the input registers last written and sends each started client its outputs.
Lockstep pacing steps as soon as every client holding inputs has answered (or
after ``lockstep_timeout_s``, a miss); real-time pacing one step per period of
the wall clock. Faults: output packages lost or delayed, the connection
closed after a number of them (:class:`~drivers.ur.emulate.rtde_server.RtdeFaults`).
``ffexp emulate --robot ur5e`` serves it through
:class:`~drivers.emulate.session.EmulatedRig`.

Sessions: a new client that starts streaming after the previous session's
clients stopped (a new ``ffexp run``, the next run of a campaign) finds the
emulator as it was started: the world of the same scene and seed at its start
pose, the program and its registers fresh (``reset_per_session``; the world is
built anew only when the last session stepped it). A client that pauses and
starts again stays in its session. So a campaign over RTDE against
one emulator runs each protocol from the same start as in-process, as an
operator re-places the target and homes the arm between runs. With
``reset_per_session=False`` the world goes on where the last session left it.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from typing import Any, Literal

from drivers.ur.emulate.controller import UrSimController
from drivers.ur.emulate.lockstep import CONTROLLER_VERSION
from drivers.ur.emulate.rtde_server import RtdeFaults, RtdeServer
from drivers.world.world import SimWorld

__all__ = ["UrEmulator"]

_POLL_S = 0.05


class UrEmulator:
    """The world's UR controller over RTDE on ``host:port`` (module docstring)."""

    def __init__(self, world: SimWorld, host: str, port: int, *,
                 pacing: Literal["realtime", "lockstep"] = "realtime",
                 lockstep_timeout_s: float = 1.0, faults: RtdeFaults | None = None,
                 where: str = "--listen", reset_per_session: bool = True) -> None:
        self.world = world
        self.controller = UrSimController(world)
        self.reset_per_session = reset_per_session
        v = CONTROLLER_VERSION
        self.server = RtdeServer(
            self._step, self._take, host=host, port=port, pacing=pacing,
            base_hz=1.0 / world.cycle_s, controller_version=(v.major, v.minor, v.bugfix, v.build),
            lockstep_timeout_s=lockstep_timeout_s, faults=faults, where=where,
            on_session=self._new_session)
        self._stop = False

    @property
    def sessions(self) -> int:
        """Sessions started so far (module docstring)."""
        return self.server.counters["sessions"]

    @property
    def steps(self) -> int:
        """World cycles run over all sessions."""
        return self.server.counters["steps"]

    def _step(self) -> Mapping[str, object]:  # the current session's program
        return self.controller.step()

    def _take(self, values: Mapping[str, Any]) -> None:
        self.controller.take(values)

    def _new_session(self) -> None:
        """A client starts the stream alone (server's thread): the world and the program
        as at the emulator's start, if the last session stepped them."""
        if self.reset_per_session and self.controller.steps:
            old = self.world
            self.world = SimWorld(old.scene, seed=old.seed)
            self.controller = UrSimController(self.world)

    @property
    def address(self) -> tuple[str, int]:
        """Where it listens (the real port when 0 was asked for)."""
        return self.server.address

    def start(self, thread: bool = True) -> UrEmulator:
        """Listen (an :class:`~drivers.errors.AddressError` naming the address) and serve
        (``thread=False``: from the first :meth:`run`, in a thread its caller starts)."""
        self.server.start(thread)
        return self

    def stop(self) -> None:
        """Make :meth:`run` return (thread-safe); the server serves on until :meth:`close`."""
        self._stop = True

    def close(self) -> None:
        """Stop serving and drop every client."""
        self._stop = True
        self.server.close()

    def run(self, max_cycles: int | None = None,
            on_cycle: Callable[[UrEmulator], None] | None = None,
            max_wall_s: float | None = None) -> None:
        """Wait while the server's thread serves: until ``max_cycles`` world cycles,
        ``max_wall_s`` of wall time without any client's session (the world steps only
        while a client streams: without one, no simulated time passes), :meth:`stop` or
        the server's error (re-raised here)."""
        end = None if max_wall_s is None else time.monotonic() + max_wall_s
        self.server.serve_in_thread()
        while not self._stop:
            if self.server.error is not None:
                raise self.server.error
            if max_cycles is not None and self.steps >= max_cycles:
                break
            if end is not None and self.sessions == 0 and time.monotonic() >= end:
                break
            if on_cycle is not None:
                on_cycle(self)
            time.sleep(_POLL_S)
        self.server.close()
        if self.server.error is not None:
            raise self.server.error

    def status(self) -> str:
        """One line: simulated time, clients, the program's and safety state, counters."""
        c, srv = self.controller, self.server
        safety = "protective stop" if c.arm.stopped else "normal"
        return (f"t={self.world.time:7.2f} s  clients {srv.clients}  script "
                f"{c.script_state.name}  safety {safety}  {self._counters()}")

    def _counters(self) -> str:
        return " ".join(f"{k} {v}" for k, v in sorted(self.server.counters.items()))

    def summary(self) -> str:
        """The server's counters in one line, with the protective stop if any."""
        stop = f"; protective stop: {self.controller.arm.stopped}" if self.controller.arm.stopped \
            else ""
        return (f"UR5e over RTDE: {self.steps} cycles in {self.sessions} sessions; "
                f"{self._counters()}{stop}")
