"""An arm's kinematics for the carrier's servo: the pose and geometric Jacobian of a frame
fixed to the flange, and inverse kinematics by damped least squares, from an arm's
published description (:class:`~drivers.description.arm.ArmDescription`). Pure maths.

A UR's ``servoJ`` takes joint targets: the carrier loop's pose set-point becomes one
through :func:`solve_ik`, started from the last target (the arm moves a few millimetres a
cycle, so two or three Newton steps converge to round-off).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drivers.base.types import F64
from drivers.carrier.body import rotation_log
from drivers.description.arm import ArmDescription, rpy_matrix

__all__ = ["ArmChain", "IkError"]


class IkError(ValueError):
    """The inverse kinematics did not reach the pose (out of reach or at a singularity)."""


@dataclass(frozen=True)
class ArmChain:
    """An arm on a base at ``base_m`` (base frame axes the world's), with a frame ``tool``
    (4x4, in the flange frame) whose pose it is asked for."""

    arm: ArmDescription
    base_m: tuple[float, float, float]
    tool: F64

    def frames(self, q: F64) -> tuple[list[F64], F64]:
        """Each joint's frame (world, 4x4, after its own turn) and the tool's pose."""
        pose = np.eye(4)
        pose[:3, 3] = self.base_m
        joints = []
        for t in self.arm.joint_transforms(q):
            pose = pose @ t
            joints.append(pose)
        flange = np.eye(4)
        flange[:3, :3] = rpy_matrix(self.arm.flange_rpy_rad)
        flange[:3, 3] = self.arm.flange_m
        return joints, pose @ flange @ self.tool

    def pose(self, q: F64) -> F64:
        """The tool frame's pose (world, 4x4)."""
        return self.frames(q)[1]

    def jacobian(self, q: F64) -> tuple[F64, F64]:
        """The tool's pose and its geometric Jacobian (6 x joints: linear velocity of the
        tool frame's origin, then angular velocity, world frame)."""
        joints, tool = self.frames(q)
        p = tool[:3, 3]
        jac = np.zeros((6, len(joints)))
        for i, (frame, axis) in enumerate(zip(joints, self.arm.joint_axes, strict=True)):
            z = frame[:3, :3] @ np.asarray(axis, dtype=np.float64)
            jac[:3, i] = np.cross(z, p - frame[:3, 3])
            jac[3:, i] = z
        return tool, jac

    def twist(self, q: F64, qd: F64) -> F64:
        """The tool frame's twist (world) at joint velocities ``qd``."""
        return np.asarray(self.jacobian(q)[1] @ qd)

    def solve_ik(self, target: F64, seed: F64, *, iterations: int = 50,
                 tol_m: float = 1e-10, damping: float = 1e-6,
                 max_step_rad: float = 0.2) -> F64:
        """Joint positions that put the tool at ``target`` (4x4), from ``seed`` (no joint
        moves more than ``max_step_rad`` a Newton step, so it stays near the seed's posture).

        Raises:
            IkError: not reached within ``iterations`` Newton steps.
        """
        q = np.array(seed, dtype=np.float64)
        err = np.inf
        for _ in range(iterations):
            tool, jac = self.jacobian(q)
            e = np.concatenate((target[:3, 3] - tool[:3, 3],
                                rotation_log(target[:3, :3] @ tool[:3, :3].T)))
            err = float(np.max(np.abs(e)))
            if err < tol_m:
                return q
            jjt = jac @ jac.T + damping * np.eye(6)
            dq = jac.T @ np.linalg.solve(jjt, e)
            q = q + dq * min(1.0, max_step_rad / max(float(np.max(np.abs(dq))), 1e-300))
        if err < 1e-7:
            return q
        raise IkError(f"inverse kinematics of the {self.arm.name}: {err:.3g} from the pose "
                      f"after {iterations} steps")

    def joint_velocity(self, q: F64, twist: F64) -> F64:
        """Joint velocities giving the tool ``twist`` (least squares)."""
        jac = self.jacobian(q)[1]
        return np.asarray(np.linalg.lstsq(jac, twist, rcond=None)[0])

