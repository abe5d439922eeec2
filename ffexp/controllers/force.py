"""Methods I and II of the paper: eq. (9), a PI force loop on the force axes and
apparent inertia reduction (positive feedback of the measured wrench) on the others.

``force_ri`` (Method I) and ``force`` (Method II, no inertia reduction: every
``k_ri`` must be zero) share the law of :class:`ffexp.controllers.laws.ForceController`.
"""

from __future__ import annotations

from typing import ClassVar, Literal

import numpy as np
from pydantic import Field, model_validator

from drivers.base.types import F64, RobotState
from drivers.config import Vec6
from ffexp.controllers.base import ControlContext, Controller
from ffexp.controllers.laws import ForceControlConfig, ForceController, ForceControlTerms
from ffexp.estimation import Estimate


class ForceRiConfig(ForceControlConfig):
    """``[align] method = "force_ri"``: Method I, eq. (9) with K_RI."""

    method: Literal["force_ri"] = "force_ri"


class ForceConfig(ForceControlConfig):
    """``[align] method = "force"``: Method II, the PI force loop alone."""

    method: Literal["force"] = "force"
    k_ri: Vec6 = Field((0.0,) * 6, description="Must stay zero: Method II has no K_RI.")

    @model_validator(mode="after")
    def _no_inertia_reduction(self) -> ForceConfig:
        if any(self.k_ri):
            raise ValueError("method 'force' (Method II) has no inertia reduction: set k_ri to 0")
        return self


class ForceRi(Controller):
    """Force control with apparent inertia reduction (Method I)."""

    name = "force_ri"
    config_model: ClassVar[type[ForceControlConfig]] = ForceRiConfig
    label = "Method I (force control + inertia reduction)"
    tracks_force_reference = True

    def __init__(self, config: ForceControlConfig, ctx: ControlContext) -> None:
        super().__init__(config, ctx)
        self.law = ForceController(config, ctx.cycle_s)
        self._f_ref = np.asarray(config.f_ref, dtype=np.float64)
        self.terms: ForceControlTerms = self.law.terms

    @property
    def f_ref(self) -> F64:
        return self._f_ref

    def enter(self, t_ns: int, state: RobotState, est: Estimate) -> None:
        self.law.reset()

    def update(self, t_ns: int, state: RobotState, est: Estimate) -> F64:
        return self.law.update(est.wrench).total


class Force(ForceRi):
    """Force control alone (Method II)."""

    name = "force"
    config_model = ForceConfig
    label = "Method II (force control)"
