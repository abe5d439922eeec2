"""The estimator's settings (the protocol's ``[estimation]``) and its output per cycle."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from pydantic import Field

from drivers.base.types import F64
from drivers.config import StrictModel
from ffexp.estimation.contact import ContactDetectorConfig, ContactEvent
from ffexp.estimation.motion_filter import MotionFilterConfig
from ffexp.estimation.tool_load import ToolLoad
from ffexp.estimation.wrench_filter import WrenchFilterConfig


class Estimation(StrictModel):
    """Filters, tool load and contact detection (the protocol's ``[estimation]``)."""

    wrench: WrenchFilterConfig = WrenchFilterConfig()
    motion: MotionFilterConfig = MotionFilterConfig()
    tool_load: ToolLoad = ToolLoad()
    inertial_compensation: bool = Field(
        True,
        description="Also remove the tool's inertia (mass x acceleration from the motion "
        "filter) from the reading; needs tool_load.mass_kg.",
    )
    contact: ContactDetectorConfig = ContactDetectorConfig()


@dataclass
class Estimate:
    """What the estimator says about one cycle (arrays are reused between cycles)."""

    wrench: F64 = field(default_factory=lambda: np.zeros(6))
    """Filtered contact wrench (environment on tool), bias and tool load removed, TCF."""
    wrench_std: F64 = field(default_factory=lambda: np.zeros(6))
    bias: F64 = field(default_factory=lambda: np.zeros(6))
    twist_tcf: F64 = field(default_factory=lambda: np.zeros(6))
    f_z: float = 0.0
    """Contact force along the approach axis, ``-wrench[2]`` [N]."""
    n_samples: int = 0
    in_contact: bool = False
    event: ContactEvent | None = None
    """Contact made or broken, confirmed this cycle."""
    tared: bool = False
    tared_now: bool = False
    """The tare happened this cycle."""
    tare_samples: int = 0
    peak_force_n: float = 0.0
    """Largest |f| of this cycle's samples (compensated, bias removed once tared)."""
    peak_torque_nm: float = 0.0
    saturated: bool = False
    """A sample of this cycle carried the sensor's saturation bit."""
    last_sample_ns: int | None = None
    """Time of the newest sample so far, on the robot's clock [ns]."""
    floats: F64 | None = field(default=None, repr=False, compare=False)
    """The estimator's output row these values are read from (its kernels' ``OF_*``
    columns), for compiled code that reads the estimate; ``None`` for an estimate made
    otherwise."""
    ints: NDArray[np.int64] | None = field(default=None, repr=False, compare=False)
    """Likewise its int row (``OI_*``)."""
