"""The ``sim`` target tracker: the simulated target's pose as a camera would report it.

Frames are taken at ``rate_hz`` on the simulator's clock; each carries the
target's pose at its exposure with Gaussian noise on the horizontal position
and the yaw (the bed plane: a camera above it sees nothing else), or, for a
target in free flight, on all three positions and as a small turn about each
axis (a marker seen in six degrees of freedom), in the arm's base frame (which
moves on a floating base); it becomes
available ``latency_s`` later; a fraction ``dropout`` of frames has no pose
(``valid`` false, the previous pose kept). The tracker is driven by the
control loop's :meth:`SimTracker.latest` (the simulator steps in lockstep),
so it needs no thread; it never blocks.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable

import numpy as np

from drivers.base.interfaces import TargetTracker
from drivers.base.types import F64, NS_PER_S, TargetObservation
from drivers.world.world import SimWorld

__all__ = ["SimTracker", "noisy_planar", "noisy_pose6"]


def noisy_planar(pose: F64, dx_m: float, dy_m: float, dyaw_rad: float) -> F64:
    """``pose`` moved by ``(dx, dy)`` in the horizontal plane and turned by ``dyaw``
    about the vertical through its origin (a new 4x4)."""
    c, s = math.cos(dyaw_rad), math.sin(dyaw_rad)
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    out = pose.copy()
    out[:3, :3] = turn @ pose[:3, :3]
    out[0, 3] += dx_m
    out[1, 3] += dy_m
    return out


def noisy_pose6(pose: F64, dp_m: F64, drot_rad: F64) -> F64:
    """``pose`` moved by ``dp_m`` and turned by the rotation vector ``drot_rad`` (both in
    the pose's parent frame, the turn about its origin; a new 4x4)."""
    from scipy.spatial.transform import Rotation

    out = pose.copy()
    out[:3, :3] = Rotation.from_rotvec(drot_rad).as_matrix() @ pose[:3, :3]
    out[:3, 3] += dp_m
    return out


class SimTracker(TargetTracker):
    """A camera-like view of the simulated target.

    Args:
        world: the simulated rig.
        clock: the robot's time now [ns] (the world's cycle times its period).
        rate_hz, latency_s, position_noise_m, yaw_noise_deg, dropout: the camera
            (``[tracker]`` of the rig, :class:`drivers.sim.backend.SimTrackerConfig`).
        seed: noise and dropout seed.
    """

    source = "sim"

    def __init__(self, world: SimWorld, clock: Callable[[], int], *, rate_hz: float,
                 latency_s: float, position_noise_m: float, yaw_noise_deg: float,
                 dropout: float, seed: int = 0) -> None:
        self.world = world
        self.clock = clock
        self.period_ns = max(1, round(NS_PER_S / rate_hz))
        self.latency_ns = round(latency_s * NS_PER_S)
        self.position_noise_m = position_noise_m
        self.yaw_noise_rad = math.radians(yaw_noise_deg)
        self.dropout = dropout
        self.rng = np.random.default_rng([seed, 0x7A6E7])
        self._pending: deque[tuple[int, TargetObservation]] = deque()
        self._latest: TargetObservation | None = None
        self._next_ns: int | None = None
        self._frames = 0
        self._mouth_in_target = np.eye(4)
        self._running = False
        self._free = world.scene.target.support == "free"

    def _target(self) -> F64:
        """The target's pose in the arm's base frame (the world's, on a fixed base)."""
        target, _ = self.world.target_frames()
        chaser = self.world.chaser
        if chaser is None:
            return target
        return chaser.in_base(target[:3, 3], target[:3, :3].reshape(9))

    def start(self) -> None:
        target, mouth = self.world.target_frames()
        self._mouth_in_target = np.linalg.inv(target) @ mouth
        self._pending.clear()
        self._latest = None
        self._next_ns = None
        self._frames = 0
        self._running = True

    def stop(self) -> None:
        self._running = False

    def _capture(self, now_ns: int) -> TargetObservation:
        self._frames += 1
        prev = self._latest
        if self.dropout > 0.0 and self.rng.random() < self.dropout:
            pose = prev.pose_m if prev is not None else np.eye(4)
            mouth = prev.mouth_m if prev is not None else np.eye(4)
            return TargetObservation(now_ns, pose, mouth, False, self.source, self._frames)
        target = self._target()
        if self._free:
            pose = noisy_pose6(target, self.rng.normal(0.0, self.position_noise_m, 3),
                               self.rng.normal(0.0, self.yaw_noise_rad, 3))
            return TargetObservation(now_ns, pose, pose @ self._mouth_in_target, True,
                                     self.source, self._frames)
        dx, dy = self.rng.normal(0.0, self.position_noise_m, 2) if self.position_noise_m else (0, 0)
        dyaw = float(self.rng.normal(0.0, self.yaw_noise_rad)) if self.yaw_noise_rad else 0.0
        pose = noisy_planar(target, float(dx), float(dy), dyaw)
        return TargetObservation(now_ns, pose, pose @ self._mouth_in_target, True, self.source,
                                 self._frames)

    def latest(self) -> TargetObservation | None:
        """Take this cycle's frame if one is due, and return the newest one available."""
        if not self._running:
            return self._latest
        now = self.clock()
        if self._next_ns is None:
            self._next_ns = now
        while now >= self._next_ns:  # one frame per period, exposed at the cycle's state
            self._pending.append((self._next_ns + self.latency_ns, self._capture(now)))
            self._next_ns += self.period_ns
        while self._pending and self._pending[0][0] <= now:
            self._latest = self._pending.popleft()[1]
        if self._latest is None:  # started, no frame yet: say so (not None: no tracker)
            return TargetObservation(now, np.eye(4), np.eye(4), False, self.source, 0)
        return self._latest
