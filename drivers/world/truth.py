"""What only the simulator knows about a cycle, in neutral form: the scene's free bodies,
its named frames, the tool's true contact and motion. Pure, no I/O.

A scenario derives its own measures from it (the funnel's placement:
:mod:`ffexp.scenarios.funnel`); nothing here knows a task.
"""

from __future__ import annotations

from collections.abc import Callable

from drivers.base.types import F64, AttachedFrame, BodyTruth, GroundTruth

__all__ = ["ground_truth", "pose"]

_pose4: Callable[[F64, F64], F64] | None = None  # kernels.pose4, imported on first use


def pose(pos: F64, mat9: F64) -> F64:
    """4x4 pose from a position and a row-major 3x3 rotation (MuJoCo's ``xmat``; 9 values
    or 3x3), a new array (compiled: :func:`drivers.world.kernels.pose4`)."""
    global _pose4
    if _pose4 is None:
        from drivers.world.kernels import pose4

        _pose4 = pose4
    return _pose4(pos, mat9 if mat9.ndim == 1 else mat9.reshape(9))


def ground_truth(bodies: dict[str, BodyTruth], sites: dict[str, F64], contact: F64,
                 touching: bool, tcp_twist: F64, base_pose: F64 | None = None,
                 attached: dict[str, AttachedFrame] | None = None) -> GroundTruth:
    """The cycle's truth from the world's bodies, frames and tool contact; ``attached``:
    which of the frames are fixed on a body (the same dict every cycle)."""
    return GroundTruth(bodies=bodies, sites=sites, contact_wrench=contact,
                       in_contact=touching, tcp_twist=tcp_twist, base_pose=base_pose,
                       attached={} if attached is None else attached)
