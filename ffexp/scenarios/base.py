"""What a scenario is: the task's geometry and the judges of its goal.

Pure: no I/O, no clock. :class:`ffexp.task.Task` owns what every scenario
shares: the phases (CONNECT, APPROACH, ALIGN, DONE/ABORT), contact breaks, the
hold time and the notes for the run log. A :class:`Scenario` owns what the
task is *about*: where the goal is and who can see it. Each cycle from the
approach on, the task asks it who judges (:meth:`Scenario.choose_source`),
lets it watch the cycle (:meth:`Scenario.observe`) and, in ALIGN, whether
its goal holds now (:meth:`Scenario.holds`); when the run ends, the
scenario says what the run achieved and why (:meth:`Scenario.final`).

A judge sees a cycle's :class:`~drivers.base.types.RobotState` (with
``truth`` in a simulator), the rig tracker's
:class:`~drivers.base.types.TargetObservation` (if any) and the estimator's
:class:`~ffexp.estimation.Estimate`. Verdict labels are the recording's
words, read by :mod:`ffexp.analysis`: ``"aligned"`` (the goal held),
``"not aligned"`` and ``"unverified"``. A scenario measures its own objects from
the truth's neutral bodies and frames (the funnel's errors) and records them on
the topics it declares (:attr:`Scenario.topics`, :meth:`Scenario.messages`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

from drivers.base.topics import CdrTopic
from drivers.base.types import RobotState, TargetObservation
from drivers.config import StrictModel
from ffexp.estimation import Estimate

if TYPE_CHECKING:
    from ffexp.protocol import RunProtocol


@dataclass(frozen=True)
class Verdict:
    """A note for ``/alignment/verdict``: who judges the goal and what it says.

    ``label`` is ``"aligned"``, ``"not aligned"`` or ``"unverified"``; ``truth`` is
    the simulator's verdict beside it (``""`` without ground truth), so a recording
    judged by a tracker or the observer can be scored against the truth.
    """

    label: str
    source: str
    reason: str
    evidence: dict[str, float]
    truth: str = ""
    final: bool = False


@dataclass(frozen=True)
class SourceChange:
    """Another judge from this cycle on: ``source`` and why (an event at ``level``)."""

    source: str
    level: str
    reason: str


class ScenarioConfig(StrictModel):
    """Base of a scenario's settings, the protocol's ``[task]`` table: ``scenario``
    names it (a subclass narrows it to ``Literal["<name>"]``), the rest are its own."""

    scenario: str


class Scenario(ABC):
    """A task's geometry and its judges (one instance per run; it keeps state).

    Class attributes: ``name`` (the registry's and the protocol's
    ``[task] scenario``), ``label`` (for tables), ``config_model`` (its
    ``[task]`` table), ``tables`` (further protocol tables it reads, fields of
    :class:`~ffexp.protocol.RunProtocol` with defaults, which other scenarios'
    protocols must leave as they are) and ``goal`` (the words of the event when
    the goal has held for :attr:`hold_s`).
    """

    name: ClassVar[str]
    label: ClassVar[str]
    config_model: ClassVar[type[ScenarioConfig]]
    tables: ClassVar[tuple[str, ...]] = ()
    goal: ClassVar[str] = "goal reached"
    topics: ClassVar[tuple[CdrTopic, ...]] = ()
    """The recording topics of its own measures (:meth:`messages`), declared here so the
    recording knows them (the scenario's observation, as dm_control's task has one)."""

    source: str | None = None
    """Who judges this cycle (``None`` before the first judged cycle)."""

    @classmethod
    def create(cls, config: ScenarioConfig, protocol: RunProtocol) -> Scenario:
        """The scenario of a run from its ``[task]`` table (and, for a scenario whose
        settings live elsewhere in the protocol, the protocol)."""
        return cls(config)  # type: ignore[call-arg]

    @property
    @abstractmethod
    def hold_s(self) -> float:
        """How long the goal must hold, without a break, for the run to have reached it."""

    def start(self, state: RobotState) -> None:  # noqa: B027 - optional hook
        """The sensor is tared with the robot commanding: the approach starts at ``state``."""

    @abstractmethod
    def choose_source(self, state: RobotState,
                      target: TargetObservation | None) -> SourceChange | None:
        """Who judges this cycle (sets :attr:`source`); a :class:`SourceChange` when that
        is another judge than last cycle's (the task then restarts its hold)."""

    def observe(  # noqa: B027 - optional hook
        self, t_ns: int, state: RobotState, est: Estimate, target: TargetObservation | None
    ) -> None:
        """Every cycle from the approach until the run ends, before the phases move."""

    def contact(self, state: RobotState) -> None:  # noqa: B027 - optional hook
        """Contact made in APPROACH: the task enters ALIGN."""

    def contact_lost(self) -> None:  # noqa: B027 - optional hook
        """Contact lost in ALIGN (a break): the task goes back to APPROACH."""

    @abstractmethod
    def holds(self, t_ns: int, state: RobotState, est: Estimate,
              target: TargetObservation | None) -> bool:
        """In ALIGN: whether the goal holds this cycle, as :attr:`source` sees it (before
        the task's hold time)."""

    def messages(self) -> list[tuple[str, object]]:
        """This cycle's messages on :attr:`topics`: ``(topic, source)``, each source's
        attributes its topic's fields by name (asked only in a cycle it observed, after
        :meth:`observe`)."""
        return []

    def truth_label(self) -> str:
        """The simulator's own verdict so far (``""`` without ground truth)."""
        return ""

    @abstractmethod
    def final(self, reached: bool) -> Verdict:
        """The run's verdict (``final=True``) when it ends; ``reached``: the goal held
        for :attr:`hold_s` at some time."""
