"""Scripted robot states and F/T samples for the loop's tests (no driver, no file)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from drivers.base.types import FtSamples, GroundTruth, LinkHealth, RobotState

CYCLE_NS = 5_000_000
T0_NS = 1_000_000_000
BIAS = np.array([0.3, -0.2, 0.5, 0.01, 0.0, 0.0])


def pose_at(z: float, y: float = 0.0) -> np.ndarray:
    """A tool pose whose TCF Z points along base +x, offset ``z`` along it."""
    pose = np.eye(4)
    pose[:3, :3] = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    pose[:3, 3] = [0.6 + z, y, 0.5]
    return pose


def cycles(
    n: int,
    contact_n: Callable[[int], float] = lambda i: 0.0,
    edit: Callable[[int, RobotState, FtSamples], None] | None = None,
    ft_until: int | None = None,
    truth: Callable[[int], GroundTruth | None] = lambda i: None,
) -> tuple[list[RobotState], list[FtSamples]]:
    """``n`` cycles of a still, commanding robot with 5 F/T samples each (bias plus noise);
    ``contact_n(i)`` is f_z in cycle i (read as w_z = -f_z)."""
    rng = np.random.default_rng(0)
    states, fts = [], []
    for i in range(n):
        s = RobotState(
            time_ns=T0_NS + i * CYCLE_NS,
            tcp_pose_m=pose_at(0.0),
            link=LinkHealth(commanding=True, healthy=True, cycle=i, cycle_s=CYCLE_NS / 1e9),
            truth=truth(i),
        )
        w = np.tile(BIAS, (5, 1)) + rng.normal(scale=0.01, size=(5, 6))
        w[:, 2] -= contact_n(i)
        ft = FtSamples(
            time_ns=s.time_ns - CYCLE_NS + np.arange(1, 6, dtype=np.int64) * 1_000_000,
            seq=np.arange(5 * i, 5 * i + 5, dtype=np.int64),
            wrench=w,
            status=np.zeros(5, dtype=np.uint32),
        )
        if edit is not None:
            edit(i, s, ft)
        states.append(s)
        fts.append(ft if ft_until is None or i < ft_until else FtSamples())
    return states, fts
