"""The paper's Section III model: one-DOF contact of a compliant manipulator
with a free-floating target.

Signs follow ``docs/conventions.md`` (the paper mixes two):

- penetration ``p = x_i - x_t`` (manipulator behind the target, moving +x),
- contact force on the target ``F_c = k_c p + b_c p'``,
- target ``m_t x_t'' = F_c - F_f``,
- manipulator ``m_ri x_i'' = -F_c - k_ri p - b_ri p'``,
- start ``x_i = x_t = 0``, ``x_i' = v0``, ``x_t' = 0``.

With ``F_f`` a constant force (the paper's table uses 0) the model is a linear
time-invariant system plus a constant input, so the bilateral (penalty) model
is solved exactly with a matrix exponential: the state is propagated by
``expm`` of the augmented system matrix over one output step, which is exact
up to floating-point rounding. "Contact break" in the penalty model is
``F_c < 0``. The unilateral variant only pushes: ``F_c = max(0, k_c p + b_c p')``
while ``p >= 0`` (touching or penetrating) and 0 otherwise; it is piecewise
linear and integrated with an adaptive Runge-Kutta method at tight tolerances.

Pure maths: no I/O, no global state.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import Field
from scipy.linalg import expm

from drivers.base.types import F64
from drivers.config import StrictModel
from ffexp.errors import SimulationError

#: Most output samples :func:`simulate` produces (about 0.6 GB of states).
MAX_SAMPLES = 20_000_001

#: Column order of :meth:`Trajectory.table` and of the CSV files.
COLUMNS = ("t", "x_i", "v_i", "x_t", "v_t", "p", "F_c")


class ContactParams(StrictModel):
    """Parameters of the 1-DOF model; defaults are the paper's Table (sim2 column)
    with the swept stiffness set to 0.

    Attributes use the paper's symbols; units are SI (kg, N/m, N s/m, m/s, N).
    """

    m_ri: float = Field(7.5, gt=0, description="Manipulator (apparent) mass [kg].")
    m_t: float = Field(15.0, gt=0, description="Target mass [kg].")
    k_ri: float = Field(0.0, ge=0, description="Manipulator passive stiffness on p [N/m].")
    b_ri: float = Field(100.0, ge=0, description="Manipulator passive damping on p' [N s/m].")
    k_c: float = Field(250.0, ge=0, description="Contact stiffness [N/m].")
    b_c: float = Field(20.0, ge=0, description="Contact damping [N s/m].")
    v0: float = Field(0.5, description="Initial manipulator velocity [m/s]; target at rest.")
    f_friction: float = Field(
        0.0, ge=0, description="Constant friction force on the target, opposing +x [N]."
    )
    unilateral: bool = Field(
        False, description="Contact only pushes: F_c = max(0, k_c p + b_c p') while p >= 0, else 0."
    )


@dataclass(frozen=True)
class Trajectory:
    """A simulated run sampled on a uniform grid.

    All arrays have the same length; ``f_c`` is the contact force on the target.
    """

    t_s: F64
    x_i: F64
    v_i: F64
    x_t: F64
    v_t: F64
    f_c: F64

    @property
    def p(self) -> F64:
        """Penetration ``x_i - x_t`` [m]."""
        return self.x_i - self.x_t

    def table(self) -> F64:
        """The run as an (N, 7) array in :data:`COLUMNS` order."""
        return np.column_stack([self.t_s, self.x_i, self.v_i, self.x_t, self.v_t, self.p, self.f_c])


@dataclass(frozen=True)
class Summary:
    """Numbers a researcher looks at first."""

    peak_f_c_n: float
    t_peak_s: float
    min_f_c_n: float
    contact_broke: bool
    break_time_s: float | None
    final_v_i_mps: float
    final_v_t_mps: float
    settling_time_s: float | None
    """Last time |F_c - F_c(end)| exceeds 2 % of the peak |F_c|; None if never inside."""


def system_matrices(params: ContactParams) -> tuple[F64, F64]:
    """State-space form ``s' = A s + c`` of the bilateral model.

    The state is ``s = [x_i, v_i, x_t, v_t]``; ``c`` is the constant input
    (friction on the target).
    """
    m_ri, m_t = params.m_ri, params.m_t
    k = params.k_c + params.k_ri  # total stiffness acting on the manipulator
    b = params.b_c + params.b_ri
    a = np.array(
        [
            [0.0, 1.0, 0.0, 0.0],
            [-k / m_ri, -b / m_ri, k / m_ri, b / m_ri],
            [0.0, 0.0, 0.0, 1.0],
            [params.k_c / m_t, params.b_c / m_t, -params.k_c / m_t, -params.b_c / m_t],
        ]
    )
    c = np.array([0.0, 0.0, 0.0, -params.f_friction / m_t])
    return a, c


def contact_force(params: ContactParams, states: F64) -> F64:
    """Contact force on the target for states of shape (..., 4)."""
    p = states[..., 0] - states[..., 2]
    p_dot = states[..., 1] - states[..., 3]
    f = params.k_c * p + params.b_c * p_dot
    if params.unilateral:
        f = np.where(p >= 0.0, np.maximum(f, 0.0), 0.0)
    return np.asarray(f, dtype=np.float64)


def simulate(params: ContactParams, duration_s: float, dt_s: float) -> Trajectory:
    """Run the model from the paper's initial conditions.

    Args:
        params: the model parameters.
        duration_s: simulated time [s], > 0.
        dt_s: output sample period [s], > 0 and <= duration_s.

    Raises:
        SimulationError: the time grid is invalid or the integrator failed.
    """
    if not (duration_s > 0.0 and dt_s > 0.0 and dt_s <= duration_s):
        raise SimulationError(f"need 0 < dt_s ({dt_s} s) <= duration_s ({duration_s} s)")
    n = round(duration_s / dt_s) + 1
    if n > MAX_SAMPLES:
        raise SimulationError(f"{n} samples is too many: raise dt_s or lower duration_s")
    t = np.arange(n, dtype=np.float64) * dt_s
    s0 = np.array([0.0, params.v0, 0.0, 0.0])
    states = _unilateral(params, s0, t) if params.unilateral else _linear(params, s0, dt_s, n)
    return Trajectory(
        t_s=t,
        x_i=states[:, 0].copy(),
        v_i=states[:, 1].copy(),
        x_t=states[:, 2].copy(),
        v_t=states[:, 3].copy(),
        f_c=contact_force(params, states),
    )


def _linear(params: ContactParams, s0: F64, dt_s: float, n: int) -> F64:
    """Exact propagation of the affine system by the augmented matrix exponential."""
    a, c = system_matrices(params)
    aug = np.zeros((5, 5))
    aug[:4, :4] = a
    aug[:4, 4] = c
    step = expm(aug * dt_s)
    out = np.empty((n, 5))
    out[0, :4] = s0
    out[0, 4] = 1.0
    for i in range(1, n):
        out[i] = step @ out[i - 1]
    return out[:, :4]


def _unilateral(params: ContactParams, s0: F64, t: F64) -> F64:
    from scipy.integrate import solve_ivp  # imported here: it costs ~0.6 s at start-up

    m_ri, m_t = params.m_ri, params.m_t

    def rhs(_t: float, s: F64) -> F64:
        f_c = float(contact_force(params, s))
        p_dot = s[1] - s[3]
        p = s[0] - s[2]
        return np.array(
            [
                s[1],
                (-f_c - params.k_ri * p - params.b_ri * p_dot) / m_ri,
                s[3],
                (f_c - params.f_friction) / m_t,
            ]
        )

    max_step = max(float(t[-1]) / 2000.0, 1e-6)
    sol = solve_ivp(
        rhs, (0.0, float(t[-1])), s0, method="DOP853", t_eval=t,
        rtol=1e-10, atol=1e-12, max_step=max_step,
    )
    if not sol.success:
        raise SimulationError(f"integrator failed: {sol.message}")
    return np.asarray(sol.y.T, dtype=np.float64)


def summarize(traj: Trajectory, settle_fraction: float = 0.02) -> Summary:
    """Peak and minimum contact force, contact break, final velocities, settling time.

    A contact break is the first sample where ``F_c < 0`` (penalty model) or,
    in the unilateral model, the first sample after t = 0 with ``F_c = 0``
    while ``p <= 0`` or the clamp is active, i.e. the bodies no longer push.
    """
    f = traj.f_c
    i_peak = int(np.argmax(f))
    broke_mask = f < 0.0
    if not broke_mask.any():
        # unilateral model: contact lost where the force returns to zero after the start
        broke_mask = np.zeros_like(f, dtype=bool)
        broke_mask[1:] = f[1:] <= 0.0
    i_break = int(np.argmax(broke_mask)) if broke_mask.any() else None
    band = settle_fraction * float(np.max(np.abs(f)))
    outside = np.flatnonzero(np.abs(f - f[-1]) > band)
    settling: float | None
    if outside.size == 0:
        settling = 0.0
    elif outside[-1] == f.size - 1:
        settling = None
    else:
        settling = float(traj.t_s[outside[-1] + 1])
    return Summary(
        peak_f_c_n=float(f[i_peak]),
        t_peak_s=float(traj.t_s[i_peak]),
        min_f_c_n=float(np.min(f)),
        contact_broke=i_break is not None,
        break_time_s=float(traj.t_s[i_break]) if i_break is not None else None,
        final_v_i_mps=float(traj.v_i[-1]),
        final_v_t_mps=float(traj.v_t[-1]),
        settling_time_s=settling,
    )
