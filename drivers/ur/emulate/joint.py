"""One arm of a shared two-arm world (:class:`drivers.emulate.shared.SharedWorld`) behind a
UR controller's RTDE port: the controller's side of :mod:`drivers.ur.joint_link`
(``servoJ`` on the joint targets of its input registers; its arm's joints and F/T samples
in its output registers), stepped in lockstep with the world's other server.

:func:`serve` is the family's ``Emulator.serve_joint``: what
:class:`drivers.emulate.twoarm.TwoArmServers` calls for each arm a UR controller serves.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from drivers.emulate.shared import SharedWorld
from drivers.errors import SimulationError
from drivers.ur.emulate.lockstep import CONTROLLER_VERSION
from drivers.ur.emulate.rtde_server import RtdeServer
from drivers.ur.joint_link import MAX_SAMPLES, input_names, output_names

__all__ = ["UrJointServer", "serve"]


class UrJointServer:
    """The role's arm of ``world`` over RTDE on ``host:port`` (lockstep)."""

    def __init__(self, world: SharedWorld, role: str, joints: int, host: str, port: int,
                 cycle_s: float, *, lockstep_timeout_s: float = 10.0) -> None:
        self.world, self.role, self.joints = world, role, joints
        v = CONTROLLER_VERSION
        self._k = 0
        self._inputs = input_names(joints)
        self.server = RtdeServer(
            self._source, self._sink, host=host, port=port, pacing="lockstep",
            base_hz=1.0 / cycle_s, outputs=output_names(joints),
            controller_version=(v.major, v.minor, v.bugfix, v.build),
            lockstep_timeout_s=lockstep_timeout_s, where=f"{role} emulator")
        self.server.start()

    @property
    def address(self) -> tuple[str, int]:
        return self.server.address

    def _sink(self, values: Mapping[str, Any]) -> None:
        regs = np.array([float(values.get(name, 0.0)) for name in self._inputs])
        self.world.set_target(self.role, regs[:self.joints], regs[self.joints:])

    def _source(self) -> Mapping[str, object]:
        reading = self.world.arrive(self.role, self._k)
        self._k += 1
        n = self.joints
        if len(reading.samples) > MAX_SAMPLES:
            raise SimulationError(f"{self.role}: {len(reading.samples)} F/T samples in one "
                                  f"cycle, the registers carry {MAX_SAMPLES}")
        regs = np.zeros(2 * n + 1 + 7 * MAX_SAMPLES)
        regs[:n], regs[n:2 * n], regs[2 * n] = reading.q, reading.qd, len(reading.samples)
        for j, (ts, wrench) in enumerate(reading.samples):
            regs[2 * n + 1 + 7 * j] = ts
            regs[2 * n + 2 + 7 * j:2 * n + 8 + 7 * j] = wrench
        out: dict[str, object] = {"timestamp": reading.t_s}
        out.update({f"output_double_register_{i}": float(v) for i, v in enumerate(regs)})
        return out

    def close(self) -> None:
        """Stop serving (its clients see the link drop) and leave the shared world."""
        self.world.leave(self.role)
        self.server.close()

    def kill(self) -> None:
        """End at once, as a controller whose process died: every connection shut down
        under its client (who reads the connection closed), the world left; returns
        without waiting for the server's thread."""
        self.world.leave(self.role)
        self.server.kill()


def serve(world: SharedWorld, role: str, joints: int, host: str, port: int,
          cycle_s: float) -> UrJointServer:
    """The role's arm behind a UR controller on ``host:port`` (0: any port)."""
    return UrJointServer(world, role, joints, host, port, cycle_s)
