"""Docking in six degrees of freedom: the funnel tool seated in the target's funnel, judged
on the full relative pose. Pure: no I/O, no clock.

The paper's funnel alignment judges a planar task (lateral offset in the bed
plane, yaw about the vertical). A target in free flight can also sit high or
low and tilt its funnel axis, so this judge measures, from the tool tip in the
funnel's mouth frame (x along the funnel axis into the target):

* ``insertion``: depth of the tip past the mouth along the funnel axis [m];
* ``radial``: distance of the tip from the funnel axis, any direction [m];
* ``tilt``: angle between the tool's approach axis (TCF Z) and the funnel axis [rad];
* ``roll``: the tool's turn about the funnel axis (reported, not judged: the cones are
  round).

The goal holds while the tip is at least ``min_insertion_m`` deep, within
``radial_tol_m`` of the axis and ``tilt_tol_deg`` of it. Who judges: the
simulator's truth (its named frames ``tcp`` and ``funnel_mouth``), else a target
tracker's mouth frame (fresh within ``tracker_max_age_s``); without either the
robot alone cannot tell where a free-floating target is, and the verdict is
``"unverified"``.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from pydantic import Field

from drivers.base.topics import CdrTopic, FieldSpec, MessageSpec
from drivers.base.types import F64, NS_PER_S, GroundTruth, RobotState, TargetObservation
from ffexp.estimation import Estimate
from ffexp.scenarios.base import Scenario, ScenarioConfig, SourceChange, Verdict
from ffexp.scenarios.funnel import MOUTH_SITE, TCP_SITE

__all__ = ["Docking6", "Docking6Task", "Pose6", "relative_pose6"]


POSE6 = MessageSpec(
    "ffexp_msgs/msg/DockingPose",
    (
        FieldSpec("insertion", "float64", 1, "m", "tool tip depth past the funnel mouth"),
        FieldSpec("radial", "float64", 1, "m", "tool tip distance from the funnel axis"),
        FieldSpec("tilt", "float64", 1, "rad", "angle between tool axis and funnel axis"),
        FieldSpec("roll", "float64", 1, "rad", "tool turn about the funnel axis"),
        FieldSpec("offset", "float64", 3, "m", "tool tip in the mouth frame"),
        FieldSpec("within", "uint8", 1, "", "within the task's tolerances this cycle"),
    ),
    "The tool tip and axis in the target funnel by the simulator's truth (docking6).",
)


class Pose6(tuple[float, float, float, float]):
    """``(insertion, radial, tilt, roll)`` of the tool in the funnel [m, m, rad, rad]."""

    __slots__ = ()

    @property
    def insertion(self) -> float:
        return self[0]

    @property
    def radial(self) -> float:
        return self[1]

    @property
    def tilt(self) -> float:
        return self[2]

    @property
    def roll(self) -> float:
        return self[3]


def relative_pose6(tcp_pose: F64, mouth_pose: F64) -> tuple[Pose6, F64]:
    """The tool (TCP pose, 4x4) in the funnel whose mouth frame is ``mouth_pose`` (same
    frame): the :class:`Pose6` and the tip's offset in the mouth frame."""
    r_mouth = mouth_pose[:3, :3]
    d = r_mouth.T @ (tcp_pose[:3, 3] - mouth_pose[:3, 3])
    axis = r_mouth[:, 0]
    tool_z = tcp_pose[:3, 2]
    tilt = math.acos(max(-1.0, min(1.0, float(tool_z @ axis))))
    # roll: the tool's X about the funnel axis, from the mouth frame's y towards its z
    tool_x = r_mouth.T @ tcp_pose[:3, 0]
    roll = math.atan2(float(tool_x[2]), float(tool_x[1]))
    return Pose6((float(d[0]), math.hypot(float(d[1]), float(d[2])), tilt, roll)), d


class Docking6Task(ScenarioConfig):
    """``[task]`` of the 6-DOF docking."""

    scenario: Literal["docking6"] = "docking6"
    source: Literal["auto", "truth", "tracker"] = Field(
        "auto", description="auto: the truth when the robot reports it, else a fresh tracker "
        "pose; without either the verdict is unverified.")
    radial_tol_m: float = Field(0.002, gt=0, description="Largest tip distance from the axis.")
    tilt_tol_deg: float = Field(2.0, gt=0, description="Largest angle between the two axes.")
    min_insertion_m: float = Field(0.02, ge=0, description="Least depth past the mouth.")
    hold_s: float = Field(0.2, ge=0, description="How long the pose must hold.")
    tracker_max_age_s: float = Field(0.25, gt=0, description="A tracker pose older than this "
                                     "does not judge.")

    def within(self, p: Pose6) -> bool:
        """``p`` within the tolerances."""
        return (p.insertion >= self.min_insertion_m and p.radial <= self.radial_tol_m
                and math.degrees(p.tilt) <= self.tilt_tol_deg)


class _Record:
    __slots__ = ("insertion", "offset", "radial", "roll", "tilt", "within")

    def __init__(self, p: Pose6, offset: F64, within: bool) -> None:
        self.insertion, self.radial, self.tilt, self.roll = p
        self.offset = offset
        self.within = int(within)


def _truth_pose(truth: GroundTruth, tcp_pose: F64) -> tuple[Pose6, F64] | None:
    mouth = truth.sites.get(MOUTH_SITE)
    if mouth is None:
        return None
    return relative_pose6(truth.sites.get(TCP_SITE, tcp_pose), mouth)


class Docking6(Scenario):
    """The 6-DOF docking's geometry and judges (truth, tracker)."""

    name = "docking6"
    label = "6-DOF docking"
    config_model = Docking6Task
    goal = "docked (6-DOF)"
    topics = (CdrTopic("/task/docking6", POSE6, "every controller cycle with ground truth"),)

    def __init__(self, config: Docking6Task) -> None:
        self.config = config
        self.source: str | None = None
        self.pose: Pose6 | None = None
        """The latest relative pose the judge used."""
        self._truth: tuple[Pose6, F64] | None = None
        self._truth_since_ns: int | None = None
        self.truth_aligned: bool | None = None

    @property
    def hold_s(self) -> float:
        return self.config.hold_s

    def _fresh(self, state: RobotState, target: TargetObservation | None) -> bool:
        return (target is not None and target.valid and state.time_ns - target.time_ns
                <= self.config.tracker_max_age_s * NS_PER_S)

    def choose_source(self, state: RobotState,
                      target: TargetObservation | None) -> SourceChange | None:
        want = self.config.source
        if want == "auto":
            src = "truth" if state.truth is not None else (
                "tracker" if self._fresh(state, target) else "none")
        elif want == "tracker" and not self._fresh(state, target):
            src = "none"
        else:
            src = want
        if src == self.source:
            return None
        old, self.source = self.source, src
        if src == "none":
            return SourceChange(src, "WARNING" if old else "INFO",
                                "no truth and no fresh tracker pose: the docking is unverified")
        return SourceChange(src, "INFO", f"{src} judges the docking")

    def observe(self, t_ns: int, state: RobotState, est: Estimate,
                target: TargetObservation | None) -> None:
        truth = state.truth
        self._truth = None if truth is None else _truth_pose(truth, state.tcp_pose_m)
        if self._truth is not None:
            if self.truth_aligned is None:
                self.truth_aligned = False
            if not self.config.within(self._truth[0]):
                self._truth_since_ns = None
            else:
                if self._truth_since_ns is None:
                    self._truth_since_ns = t_ns
                if t_ns - self._truth_since_ns >= self.config.hold_s * NS_PER_S:
                    self.truth_aligned = True
        if self.source == "truth":
            self.pose = None if self._truth is None else self._truth[0]
        elif self.source == "tracker" and target is not None:
            self.pose = relative_pose6(state.tcp_pose_m, target.mouth_m)[0]

    def contact_lost(self) -> None:
        self._truth_since_ns = None

    def messages(self) -> list[tuple[str, object]]:
        if self._truth is None:
            return []
        p, d = self._truth
        return [("/task/docking6", _Record(p, np.asarray(d), self.config.within(p)))]

    def holds(self, t_ns: int, state: RobotState, est: Estimate,
              target: TargetObservation | None) -> bool:
        return (self.source in ("truth", "tracker") and self.pose is not None
                and self.config.within(self.pose))

    def truth_label(self) -> str:
        if self.truth_aligned is None:
            return ""
        return ("aligned" if self.truth_aligned or self._truth_since_ns is not None
                else "not aligned")

    def final(self, reached: bool) -> Verdict:
        src = self.source or "none"
        truth = self.truth_label()
        if src == "none":
            return Verdict("aligned" if reached else "unverified", src,
                           "the robot alone cannot tell where a free-floating target is",
                           {}, truth, True)
        p = self.pose
        evidence = {} if p is None else {
            "insertion_m": p.insertion, "radial_m": p.radial,
            "tilt_deg": math.degrees(p.tilt), "roll_deg": math.degrees(p.roll)}
        hold = self.config.hold_s
        reason = (f"{src}: tool within tolerance of the funnel for {hold} s" if reached
                  else f"{src}: never within tolerance for {hold} s")
        return Verdict("aligned" if reached else "not aligned", src, reason, evidence, truth,
                       True)
