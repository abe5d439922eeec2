"""Method III of the paper: the approach's impedance law kept through contact."""

from __future__ import annotations

from typing import Literal

from drivers.base.types import F64, RobotState
from drivers.config import StrictModel
from ffexp.controllers.base import Controller
from ffexp.estimation import Estimate


class ImpedanceAlignConfig(StrictModel):
    """``[align] method = "impedance"``: no settings of its own (``[approach]`` applies)."""

    method: Literal["impedance"] = "impedance"


class _Terms:
    def __init__(self, wrench: F64) -> None:
        self.impedance = wrench


class Impedance(Controller):
    """The approach line continues: set-point and time as if contact had not happened."""

    name = "impedance"
    config_model = ImpedanceAlignConfig
    label = "Method III (impedance control)"
    continues_approach = True  # the paper, sec. V: "for method (iii) there was no
    # switching of control mode"; its set-point follows one straight line

    def enter(self, t_ns: int, state: RobotState, est: Estimate) -> None:
        """Nothing to reset: the line keeps its anchor."""

    def update(self, t_ns: int, state: RobotState, est: Estimate) -> F64:
        approach = self.ctx.approach
        wrench = approach.command(t_ns, state.tcp_pose_m, est.twist_tcf)
        self.terms = _Terms(wrench)
        return wrench
