"""Admittance control (not in the paper): a virtual mass-damper driven by the measured wrench.

Per admittance axis ``j`` (a TCF axis of the pose where ALIGN began), the
virtual set-point offset ``x_v`` and its velocity ``v`` follow

    M_j v' = d_j - D_j v,        x_v' = v,

with the drive ``d = W (F_ref - F_c) + (I - W) w`` (``F_c = -w``: on the force
axes the force error, elsewhere the wrench the environment exerts on the
tool, so the set-point yields to it), integrated semi-implicitly at the
controller cycle. The robot is pulled to the moving set-point by a spring
and damper of its own, sent as the superposed wrench:

    F_cmd = K (x_sp - x) - B x',    x_sp = pose_entry * (x_v),

so in steady contact on a force axis ``F_c = F_ref`` (the set-point stops
when the error vanishes). Axes outside ``axes`` are left to the robot's own
impedance.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field, model_validator
from scipy.spatial.transform import Rotation

from drivers.base.types import F64, RobotState
from drivers.config import Bool6, StrictModel, Vec6
from ffexp.controllers.base import ControlContext, Controller
from ffexp.controllers.laws import AXES, pose_error_tcf
from ffexp.estimation import Estimate
from ffexp.recording.topics import CDR_TOPICS


class AdmittanceConfig(StrictModel):
    """``[align] method = "admittance"``."""

    method: Literal["admittance"] = "admittance"
    axes: Bool6 = Field(
        (False, True, True, True, False, False),
        description="TCF axes the admittance acts on (default Y, Z, rot-X: the bed plane).",
    )
    force_axes: Bool6 = Field(
        (False, False, True, False, False, False), description="Axes driven by F_ref - F_c."
    )
    f_ref: Vec6 = Field((0.0, 0.0, 0.8, 0.0, 0.0, 0.0), description="F_ref [N, N m].")
    mass: Vec6 = Field(
        (2.0, 2.0, 2.0, 0.02, 0.02, 0.02), description="Virtual mass [kg, kg m^2]."
    )
    damping: Vec6 = Field(
        (40.0, 40.0, 40.0, 0.4, 0.4, 0.4), description="Virtual damping [N s/m, N m s/rad]."
    )
    stiffness: Vec6 = Field(
        (300.0, 300.0, 300.0, 3.0, 3.0, 3.0),
        description="Spring pulling the tool to the set-point [N/m, N m/rad].",
    )
    tracking_damping: Vec6 = Field(
        (10.0, 10.0, 10.0, 0.1, 0.1, 0.1), description="Damper of that spring [N s/m, N m s/rad]."
    )
    output_limit: Vec6 = Field(
        (20.0, 20.0, 20.0, 2.0, 2.0, 2.0), description="|F_cmd| limit per axis [N, N m]."
    )

    @model_validator(mode="after")
    def _consistent(self) -> AdmittanceConfig:
        for i, axis in enumerate(AXES):
            if self.axes[i] and (self.mass[i] <= 0.0 or self.damping[i] < 0.0):
                raise ValueError(f"mass[{i}] ({axis}) must be > 0 and damping >= 0")
            if self.force_axes[i] and not self.axes[i]:
                raise ValueError(f"force_axes[{i}] ({axis}) must also be an admittance axis")
            if not self.force_axes[i] and self.f_ref[i]:
                raise ValueError(f"f_ref[{i}] ({axis}) must be 0 outside the force axes")
        return self


class VirtualState:
    """The admittance's own terms (recorded on ``/control/admittance``)."""

    def __init__(self) -> None:
        self.drive = np.zeros(6)
        self.velocity = np.zeros(6)
        self.displacement = np.zeros(6)


class MassDamper:
    """``M v' = d - D v``, ``x' = v`` per axis, semi-implicit Euler at ``dt_s``. Pure maths."""

    def __init__(self, mass: F64, damping: F64, dt_s: float) -> None:
        self.mass = mass
        self.damping = damping
        self.dt_s = dt_s
        self.state = VirtualState()

    def reset(self) -> None:
        s = self.state
        s.velocity[:] = 0.0
        s.displacement[:] = 0.0

    def step(self, drive: F64) -> VirtualState:
        s = self.state
        s.drive[...] = drive
        # implicit in the damping (stable for any D dt / M), explicit in the drive
        s.velocity[...] = (s.velocity + self.dt_s * drive / self.mass) / (
            1.0 + self.dt_s * self.damping / self.mass
        )
        s.displacement += self.dt_s * s.velocity
        return s


class Admittance(Controller):
    """A virtual mass-damper set-point the robot is pulled to."""

    name = "admittance"
    config_model = AdmittanceConfig
    label = "Admittance control (virtual mass-damper)"
    tracks_force_reference = True
    topic = CDR_TOPICS["/control/admittance"]

    def __init__(self, config: AdmittanceConfig, ctx: ControlContext) -> None:
        super().__init__(config, ctx)
        self.cfg = config
        self._axes = np.asarray(config.axes, dtype=np.float64)
        self._w_sel = np.asarray(config.force_axes, dtype=np.float64)
        self._f_ref = np.asarray(config.f_ref, dtype=np.float64)
        self._k = self._axes * np.asarray(config.stiffness, dtype=np.float64)
        self._b = self._axes * np.asarray(config.tracking_damping, dtype=np.float64)
        self._lim = np.asarray(config.output_limit, dtype=np.float64)
        self.model = MassDamper(
            np.asarray(config.mass, dtype=np.float64),
            np.asarray(config.damping, dtype=np.float64),
            ctx.cycle_s,
        )
        self.extra = self.model.state
        self._entry = np.eye(4)
        self._sp = np.eye(4)

    @property
    def f_ref(self) -> F64:
        return self._f_ref

    def enter(self, t_ns: int, state: RobotState, est: Estimate) -> None:
        self._entry = state.tcp_pose_m.copy()
        self.model.reset()

    def drive(self, w: F64) -> F64:
        """``W (F_ref - F_c) + (I - W) w`` on the admittance axes (``F_c = -w``)."""
        out: F64 = self._axes * (self._w_sel * (self._f_ref + w) + (1.0 - self._w_sel) * w)
        return out

    def setpoint(self) -> F64:
        """The entry pose moved by the virtual displacement (in the entry TCF)."""
        x = self.model.state.displacement
        e = self._entry
        sp = self._sp
        sp[:3, :3] = e[:3, :3] @ Rotation.from_rotvec(x[3:]).as_matrix()
        sp[:3, 3] = e[:3, 3] + e[:3, :3] @ x[:3]
        return sp

    def update(self, t_ns: int, state: RobotState, est: Estimate) -> F64:
        self.model.step(self.drive(est.wrench))
        err = pose_error_tcf(state.tcp_pose_m, self.setpoint())
        out: F64 = np.clip(self._k * err - self._b * est.twist_tcf, -self._lim, self._lim)
        return out
