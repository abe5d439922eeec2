"""A diverging MuJoCo state made visible (an error) and quiet (no reset, no log file).

By default MuJoCo answers a NaN/huge ``qpos``/``qvel``/``qacc`` by resetting
the data (``mj_resetData``: time jumps back to 0, the state to the model's)
and writing the first warning of each kind to stderr and ``MUJOCO_LOG.TXT``
in the working directory. :func:`quiet_divergence` disables the auto-reset
(so the bad state stays and the step keeps its time) and starts the three
warning counters at 1 (MuJoCo writes a warning only when its counter is 0);
:func:`check_divergence` raises when a counter moved. Neither changes the
physics of a run that does not diverge.
"""

from __future__ import annotations

import mujoco
import numpy as np
from numpy.typing import NDArray

from drivers.errors import SimulationError

__all__ = ["check_divergence", "quiet_divergence"]

#: MuJoCo's bad-state warnings: (what went bad, index into ``mjData.warning``).
_BAD_STATE_WARNINGS = (
    ("qacc", int(mujoco.mjtWarning.mjWARN_BADQACC)),
    ("qpos", int(mujoco.mjtWarning.mjWARN_BADQPOS)),
    ("qvel", int(mujoco.mjtWarning.mjWARN_BADQVEL)),
)
_SEEN = 1
_I_QACC, _I_QPOS, _I_QVEL = (i for _, i in _BAD_STATE_WARNINGS)


def quiet_divergence(m: mujoco.MjModel, d: mujoco.MjData) -> None:
    """No auto-reset, and the bad-state warning counters primed (module docstring)."""
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_AUTORESET)
    for _, i in _BAD_STATE_WARNINGS:
        d.warning[i].number = _SEEN


def check_divergence(d: mujoco.MjData, number: NDArray[np.int32] | None = None) -> None:
    """Raise if MuJoCo flagged a bad state since the last check.

    ``number``: ``d.warning.number`` (a view into ``d``; given, it is not looked up).

    Raises:
        SimulationError: naming the simulated time and the bad quantities.
    """
    if number is None:
        number = d.warning.number
    if number[_I_QACC] == _SEEN and number[_I_QPOS] == _SEEN and number[_I_QVEL] == _SEEN:
        return
    w = d.warning
    bad = [name for name, i in _BAD_STATE_WARNINGS if number[i] != _SEEN]
    if bad:
        for _, i in _BAD_STATE_WARNINGS:
            w[i].number = _SEEN
        raise SimulationError(
            f"physics diverged at t = {d.time:.4f} s: "
            f"{', '.join(bad)} not finite or huge (MuJoCo warnings)"
        )
