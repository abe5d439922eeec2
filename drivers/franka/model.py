"""The FR3's rigid-body model from its description, for the driver's impedance law. Pure maths.

The driver closes the Cartesian impedance law itself at 1 kHz, so it needs what a KRC
computes inside: the TCP's Jacobian in the TCF and the joint-space mass matrix (for the
Cartesian inertia the damping ratio is taken against). Both come from the published
description (:data:`drivers.description.fr3.FR3`): the chain's frames, the links' masses,
centres of mass and principal inertias, and the drives' reflected inertias on the
diagonal of the mass matrix (``M = sum_k m_k Jv_k^T Jv_k + Jw_k^T R_k I_k R_k^T Jw_k``
plus the rotors).

:meth:`ArmModel.jacobian_tcf` is one compiled call (:mod:`drivers.franka.kernels`, bit for
bit :meth:`~ArmModel.jacobian_tcf_numpy`), and answers a second call for the same joints
and tool (the driver's state and the law's cycle read the same state) with the same
arrays.
"""

from __future__ import annotations

import numpy as np

from drivers.base.types import F64
from drivers.carrier.body import cross3
from drivers.description.arm import ArmDescription
from drivers.description.fr3 import FR3

__all__ = ["ArmModel"]


class ArmModel:
    """Kinematics and mass matrix of ``arm`` (the FR3 by default), in its base frame."""

    def __init__(self, arm: ArmDescription = FR3) -> None:
        self.arm = arm
        self.n = arm.joints
        self._masses = np.asarray(arm.link_masses_kg, dtype=np.float64)
        self._coms = np.asarray(arm.link_coms_m, dtype=np.float64)
        self._inertias = np.asarray(arm.link_inertias_kgm2, dtype=np.float64)
        rotors = arm.rotor_inertias_kgm2 or (0.0,) * self.n
        self._rotors = np.diag(np.asarray(rotors, dtype=np.float64))
        self._flange = np.eye(4)
        self._flange[:3, 3] = arm.flange_m
        # per joint, its axis as an array, and per link its principal inertia as a
        # diagonal matrix (made once, not per call)
        self._axes = [np.asarray(a, dtype=np.float64) for a in arm.joint_axes]
        self._inertia_diags = [np.diag(i) for i in self._inertias]
        # the compiled Jacobian's inputs (drivers.franka.kernels: numba, imported here)
        from drivers.franka.kernels import tcf_jacobian

        self._tcf_jacobian = tcf_jacobian
        self._turns = np.array(arm._fixed_turns, dtype=np.float64).reshape(self.n, 3, 3)
        self._origins = np.array(arm.joint_origins_m, dtype=np.float64).reshape(self.n, 3)
        self._axes_int = np.array(arm.joint_axes, dtype=np.int64).reshape(self.n, 3)
        self._jac_key: tuple[bytes, bytes] | None = None
        self._jac_last: tuple[F64, F64] | None = None

    def frames(self, q: F64) -> list[F64]:
        """Each link frame's pose in the base frame (4x4), links 1..n."""
        out = []
        pose = np.eye(4)
        for t in self.arm.joint_transforms(q):
            pose = pose @ t
            out.append(pose)
        return out

    def tcp_pose(self, q: F64, flange_to_tcp: F64) -> F64:
        """The TCP's pose in the base frame: the flange, then ``flange_to_tcp`` (4x4)."""
        return np.asarray(self.frames(q)[-1] @ self._flange @ flange_to_tcp, dtype=np.float64)

    def jacobian_tcf(self, q: F64, flange_to_tcp: F64) -> tuple[F64, F64]:
        """``(J, tcp pose)``: the 6xn Jacobian mapping joint speeds to the TCP's twist
        ``[v, w]`` in the TCF, and the TCP's pose in the base frame (read-only arrays:
        the same ones while ``q`` and ``flange_to_tcp`` are)."""
        key = (q.tobytes(), flange_to_tcp.tobytes())
        if key != self._jac_key or self._jac_last is None:
            jac, tcp = np.empty((6, self.n)), np.empty((4, 4))
            self._tcf_jacobian(np.asarray(q, dtype=np.float64), self._turns, self._origins,
                               self._axes_int, self._flange,
                               np.asarray(flange_to_tcp, dtype=np.float64), jac, tcp)
            jac.flags.writeable = tcp.flags.writeable = False
            self._jac_key, self._jac_last = key, (jac, tcp)
        return self._jac_last

    def jacobian_tcf_numpy(self, q: F64, flange_to_tcp: F64) -> tuple[F64, F64]:
        """:meth:`jacobian_tcf` in numpy (the reference the compiled form equals)."""
        frames = self.frames(q)
        tcp = frames[-1] @ self._flange @ flange_to_tcp
        p = tcp[:3, 3]
        jac = np.empty((6, self.n))
        for i, f in enumerate(frames):
            z = f[:3, :3] @ self._axes[i]
            jac[:3, i] = cross3(z, p - f[:3, 3])
            jac[3:, i] = z
        r_t = tcp[:3, :3].T
        jac[:3] = r_t @ jac[:3]
        jac[3:] = r_t @ jac[3:]
        return jac, np.asarray(tcp, dtype=np.float64)

    def mass_matrix(self, q: F64) -> F64:
        """The joint-space mass matrix (nxn) at ``q``, the drives' inertia included."""
        frames = self.frames(q)
        origins = [f[:3, 3] for f in frames]
        axes = [f[:3, :3] @ a for f, a in zip(frames, self._axes, strict=True)]
        m = self._rotors.copy()
        for k, f in enumerate(frames):
            r = f[:3, :3]
            c = f[:3, 3] + r @ self._coms[k]
            jv = np.zeros((3, self.n))
            jw = np.zeros((3, self.n))
            for i in range(k + 1):
                jv[:, i] = cross3(axes[i], c - origins[i])
                jw[:, i] = axes[i]
            inertia = r @ self._inertia_diags[k] @ r.T
            m += self._masses[k] * jv.T @ jv + jw.T @ inertia @ jw
        return m
