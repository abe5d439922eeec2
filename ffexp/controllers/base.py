"""What every method of the ALIGN phase implements, and the approach line they may reuse.

A controller turns the robot state and the estimate into the superposed
wrench (TCF, environment-on-tool sign conventions of ``docs/conventions.md``)
once per cycle. Its :attr:`Controller.terms` is an object whose attributes
named like the fields of ``/control/terms`` (``p``, ``i``, ``ri``, ``ff``,
``impedance``, ``saturated``) are recorded there; terms of its own go on
:attr:`Controller.topic`, a topic it declares, from same-named attributes of
:attr:`Controller.extra`.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from drivers.base.types import F64, NS_PER_S, RobotState
from drivers.config import StrictModel
from ffexp.controllers.laws import ImpedanceConfig, ImpedanceController
from ffexp.estimation import Estimate
from ffexp.recording.schema import CdrTopic


class Approach:
    """The approach phase's impedance law along a line anchored where the phase starts."""

    def __init__(self, config: ImpedanceConfig) -> None:
        self.law = ImpedanceController(config)
        self.wrench = np.zeros(6)
        self._start_ns = 0

    @property
    def setpoint(self) -> F64:
        return self.law.setpoint

    def start(self, t_ns: int, pose: F64) -> None:
        """Anchor the line at ``pose`` (4x4) at run time ``t_ns``."""
        self._start_ns = t_ns
        self.law.start(pose)

    def command(self, t_ns: int, pose: F64, twist_tcf: F64, out: F64 | None = None) -> F64:
        """The law's wrench ``t_ns`` into the line, into ``out`` (a 6-vector; by default
        :attr:`wrench`) and returned."""
        return self.law.update(pose, twist_tcf, (t_ns - self._start_ns) / NS_PER_S,
                               self.wrench if out is None else out)


@dataclass
class ControlContext:
    """What a controller may use besides its config."""

    cycle_s: float
    approach: Approach


class Controller(abc.ABC):
    """One method of the ALIGN phase (registered in :mod:`ffexp.controllers`)."""

    name: ClassVar[str]
    """The ``[align] method`` value."""
    config_model: ClassVar[type[StrictModel]]
    """Its ``[align]`` table (``method: Literal["<name>"]`` and the method's settings)."""
    label: ClassVar[str]
    """How tables and figures name the method."""
    tracks_force_reference: ClassVar[bool] = False
    """Whether f_z tracking of ``f_ref`` is a meaningful metric of this method."""
    continues_approach: ClassVar[bool] = False
    """The method is the approach's law carried on (no switch of control mode at contact),
    so a contact break does not restart the approach line: it goes on from its anchor."""
    topic: ClassVar[CdrTopic | None] = None
    """A topic of the method's own terms, written every cycle in ALIGN."""

    def __init__(self, config: StrictModel, ctx: ControlContext) -> None:
        self.config = config
        self.ctx = ctx
        self.terms: object = None
        self.extra: object = None

    @property
    def f_ref(self) -> F64:
        """The force reference recorded on ``/control/terms`` (zeros if none)."""
        return np.zeros(6)

    @abc.abstractmethod
    def enter(self, t_ns: int, state: RobotState, est: Estimate) -> None:
        """The ALIGN phase starts (contact made)."""

    @abc.abstractmethod
    def update(self, t_ns: int, state: RobotState, est: Estimate) -> F64:
        """The superposed wrench for this cycle (TCF) [N, N m]."""
