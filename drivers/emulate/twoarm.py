"""Both arms of a rendered-target impact, each behind its own emulated controller, on one
simulated world (:mod:`drivers.carrier.plant`, :class:`~drivers.emulate.shared.SharedWorld`):
the chaser's and the carrier's, in lockstep. Each role names a family's emulator
(:func:`drivers.registry.emulator`: ``ur5e``, ...) whose entry serves one arm of a shared
world (``Emulator.serve_joint``); this module names no family::

    with TwoArmServers(scene, layout, chaser=("ur5e", "127.0.0.3", 0),
                       carrier=("ur5e", "127.0.0.2", 0)) as servers:
        servers.address("carrier")   # where the carrier's link connects
"""

from __future__ import annotations

from importlib import import_module
from types import TracebackType
from typing import Any

from drivers import registry
from drivers.carrier.plant import ArmLayout
from drivers.description.scene import Scene
from drivers.emulate.shared import ROLES, SharedWorld
from drivers.errors import ConfigError
from drivers.world.twoarm import TwoArmWorld

__all__ = ["TwoArmServers"]


class TwoArmServers:
    """The two-arm world and one server per role (``(emulator, host, port)`` each)."""

    def __init__(self, scene: Scene, layout: ArmLayout, *, chaser: tuple[str, str, int],
                 carrier: tuple[str, str, int], seed: int = 0,
                 timeout_s: float = 10.0) -> None:
        self.world = SharedWorld(TwoArmWorld(scene, layout, seed), layout.chaser_q0,
                                 layout.carrier_q0, timeout_s=timeout_s)
        joints = {"chaser": layout.chaser.arm.joints, "carrier": layout.carrier.arm.joints}
        self.servers: dict[str, Any] = {}
        try:
            for role, (name, host, port) in zip(ROLES, (chaser, carrier), strict=True):
                entry = registry.emulator(name)
                if entry.serve_joint is None:
                    raise ConfigError(f"{role}.emulator", name,
                                      "this controller serves no arm of a shared world")
                module, func = entry.serve_joint.split(":")
                self.servers[role] = getattr(import_module(module), func)(
                    self.world, role, joints[role], host, port, scene.carrier.cycle_s)
        except BaseException:
            self.close()
            raise

    def address(self, role: str) -> tuple[str, int]:
        """Where the role's controller listens."""
        host, port = self.servers[role].address
        return str(host), int(port)

    def kill(self, role: str) -> None:
        """End the role's emulator at once (its client reads the connection closed)."""
        self.servers[role].kill()

    def close(self) -> None:
        for server in self.servers.values():
            server.close()
        self.servers = {}

    def __enter__(self) -> TwoArmServers:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()
