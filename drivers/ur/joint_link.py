"""An arm's joint-position link over RTDE (:class:`drivers.carrier.plant.JointLink`): each
cycle the controller's outputs give the arm's joints and the F/T samples that reached it,
and the answer sets the joint targets in input registers, which ffexp's program turns into
``servoJ`` (the emulated side: :mod:`drivers.ur.emulate.joint`).

The register map (doubles; ``n`` joints, at most :data:`MAX_SAMPLES` samples a cycle):

- inputs ``input_double_register_0 .. n-1`` the joint targets [rad], ``n .. 2n-1`` their
  velocities [rad/s];
- outputs ``timestamp``; ``output_double_register_0 .. n-1`` the joints' positions,
  ``n .. 2n-1`` their velocities, ``2n`` the number of F/T samples, then per sample its
  time [s] and wrench (6: N, N m).

Doubles cross RTDE as they are (big-endian IEEE 754), so a run over this link equals the
same run in process bit for bit.
"""

from __future__ import annotations

from typing import Final

import numpy as np

from drivers.base.types import F64
from drivers.carrier.plant import JointReading
from drivers.errors import DriverError, LinkLostError
from drivers.ur.rtde.client import RtdeClient
from drivers.ur.rtde.fields import Recipe

__all__ = ["MAX_SAMPLES", "UrJointLink", "input_names", "output_names"]

#: The most F/T samples a cycle's outputs carry.
MAX_SAMPLES: Final = 4


def input_names(joints: int) -> tuple[str, ...]:
    """The input recipe of an arm of ``joints`` joints."""
    return tuple(f"input_double_register_{i}" for i in range(2 * joints))


def output_names(joints: int) -> tuple[str, ...]:
    """The output recipe of an arm of ``joints`` joints."""
    n = 2 * joints + 1 + 7 * MAX_SAMPLES
    return ("timestamp", *(f"output_double_register_{i}" for i in range(n)))


class UrJointLink:
    """One arm's joint link to an RTDE controller at ``host:port``."""

    def __init__(self, role: str, host: str, port: int, joints: int, *,
                 frequency_hz: float = 500.0, timeout_s: float = 5.0) -> None:
        self.name = f"{role} at {host}:{port}"
        self.joints = joints
        self.client = RtdeClient(host, port, timeout_s=timeout_s)
        self.client.connect()
        self._out: Recipe = self.client.setup_outputs(output_names(joints), frequency_hz)
        self._in: Recipe = self.client.setup_inputs(input_names(joints))
        self.client.start()
        self._closed = False

    def read(self) -> JointReading:
        if self._closed:
            raise LinkLostError(f"{self.name}: link closed")
        try:
            rec = self.client.receive().record
        except DriverError:
            raise
        n = self.joints
        regs = np.array([float(rec[f"output_double_register_{i}"])
                         for i in range(2 * n + 1 + 7 * MAX_SAMPLES)])
        count = int(regs[2 * n])
        samples = [(float(regs[2 * n + 1 + 7 * j]),
                    regs[2 * n + 2 + 7 * j:2 * n + 8 + 7 * j].copy()) for j in range(count)]
        return JointReading(float(rec["timestamp"]), regs[:n].copy(), regs[n:2 * n].copy(),
                            samples)

    def send(self, q: F64, qd: F64) -> None:
        values = {name: float(v) for name, v in zip(input_names(self.joints),
                                                    (*q, *qd), strict=True)}
        self.client.send(self._in, values)

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self.client.close()
