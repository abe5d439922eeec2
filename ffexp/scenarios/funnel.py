"""The paper's scenario: a funnel-shaped tool aligned with the funnel on a floating target.

Pure: no I/O, no clock. The goal: the tool inside the target's funnel, its
lateral and yaw errors within tolerance past ``min_insertion_m``. The verdict
comes from whichever source sees the target (``[alignment] source =
"auto"``): ground truth in a simulator; else the rig's target tracker, from
the relative pose of the tool and the tracked funnel mouth
(:mod:`drivers.base.placement`); else the wrench-and-kinematics observer
(:mod:`ffexp.observer`), which says "aligned", "not aligned" or
"unverified". Truth and tracker share one set of tolerances. A tracker pose
that is lost or older than ``tracker_max_age_s`` hands the verdict to the
observer until a fresh one arrives (an event says so). The truth's verdict
is kept beside whoever judges (simulation), so a run judged by a tracker or
the observer can be scored against it.

Its settings are the protocol's ``[alignment]`` table (:class:`Alignment`),
where they have always been; its ``[task]`` table names only the scenario.
"""

from __future__ import annotations

import math
from types import ModuleType
from typing import TYPE_CHECKING, Literal

import numpy as np
from pydantic import Field

from drivers.base.placement import Placement, placement
from drivers.base.topics import CdrTopic, FieldSpec, MessageSpec
from drivers.base.types import NS_PER_S, GroundTruth, RobotState, TargetObservation
from drivers.config import StrictModel
from ffexp.estimation import Estimate
from ffexp.observer import ObserverLimits, WrenchObserver
from ffexp.scenarios.base import Scenario, ScenarioConfig, SourceChange, Verdict

if TYPE_CHECKING:
    from ffexp.protocol import RunProtocol

Source = Literal["truth", "tracker", "observer", "settings"]

#: The simulator's named frame of the target funnel's mouth (x along the funnel axis).
MOUTH_SITE = "funnel_mouth"
#: The simulator's named frame of the true TCP (a robot's measured pose may lag it).
TCP_SITE = "tcp"

PLACEMENT = MessageSpec(
    "ffexp_msgs/msg/FunnelPlacement",
    (
        FieldSpec("insertion", "float64", 1, "m", "tool tip depth past the funnel mouth"),
        FieldSpec("lateral", "float64", 1, "m", "tool tip offset from the funnel axis, "
                  "horizontal"),
        FieldSpec("vertical", "float64", 1, "m", "tool tip offset from the funnel axis, "
                  "vertical"),
        FieldSpec("yaw", "float64", 1, "rad", "tool axis heading minus funnel axis heading"),
        FieldSpec("within", "uint8", 1, "", "within the [alignment] tolerances this cycle"),
    ),
    "The tool tip in the target funnel by the simulator's truth (funnel alignment).",
)


def kernels() -> ModuleType:
    """:mod:`ffexp.controllers.kernels` (its :func:`funnel_geometry`), imported on first
    use (numba's import is slow)."""
    from ffexp.controllers import kernels as module

    return module


def truth_placement(truth: GroundTruth, tcp_pose: np.ndarray) -> Placement | None:
    """The tool tip in the funnel from the simulator's truth (``None``: no funnel mouth); the
    truth's own TCP frame when it has one, else ``tcp_pose`` (the robot's measurement)."""
    mouth = truth.sites.get(MOUTH_SITE)
    if mouth is None:
        return None
    return placement(truth.sites.get(TCP_SITE, tcp_pose), mouth)


class _PlacementRecord:
    """``/task/funnel``'s fields."""

    __slots__ = ("insertion", "lateral", "vertical", "within", "yaw")

    def __init__(self, p: Placement, within: bool) -> None:
        self.fill(p, within)

    def fill(self, p: Placement, within: bool) -> None:
        self.insertion, self.lateral, self.vertical, self.yaw = p
        self.within = int(within)


class Alignment(StrictModel):
    """When the funnels count as aligned, and who judges it.

    One set of tolerances (lateral, yaw, insertion, ``hold_s``) for every source
    that sees the target: ground truth (a simulator) and a target tracker (the
    relative pose of the tool and the tracked funnel mouth). Without either,
    the observer (:mod:`ffexp.observer`) judges with its own thresholds.
    """

    source: Literal["auto", "truth", "tracker", "observer", "settings"] = Field(
        "auto", description="auto: ground truth when the robot reports it, else the tracker "
        "when the rig has one, else the observer. settings: the old rule (advance "
        "seated_depth_m since first contact with |f_y| <= lateral_force_n), kept for "
        "comparison; it calls runs aligned that are not.")
    lateral_tol_m: float = Field(0.002, gt=0)
    yaw_tol_deg: float = Field(2.0, gt=0)
    min_insertion_m: float = Field(0.02, ge=0)
    hold_s: float = Field(0.2, ge=0)
    tracker_max_age_s: float = Field(
        0.25, gt=0, description="A tracker pose older than this does not judge (the observer "
        "does until a fresh one arrives).")
    seated_depth_m: float = Field(
        0.03, gt=0, description="Observer: insertion the funnels have when seated [m].")
    lateral_force_n: float = Field(0.3, gt=0, description="Observer: largest |f_y| when seated.")
    lateral_torque_nm: float = Field(
        0.05, gt=0, description="Observer: largest |t_x| (about the vertical) when seated.")
    wall_force_ratio: float = Field(
        0.5, gt=0, description="Observer: |f_y| / f_z at or above which (with |f_y| above "
        "lateral_force_n) the tool rests on one wall of the funnel: not aligned.")
    min_force_n: float = Field(0.3, ge=0, description="Observer: the tool must push this hard.")
    lateral_speed_mps: float = Field(
        0.002, gt=0, description="Observer: largest tool speed along Y when seated.")
    yaw_rate_dps: float = Field(1.0, gt=0, description="Observer: largest tool yaw rate.")
    observer_hold_s: float = Field(
        1.0, ge=0, description="Observer: how long its evidence must hold.")
    target_mass_kg: float = Field(
        12.0, gt=0, description="Observer: the target's mass (bounds how far pushing moved it).")

    def within(self, p: Placement) -> bool:
        """The tool tip at ``p`` within the lateral, yaw and insertion tolerances."""
        return (abs(p.lateral) <= self.lateral_tol_m
                and abs(math.degrees(p.yaw)) <= self.yaw_tol_deg
                and p.insertion >= self.min_insertion_m)


class FunnelTask(ScenarioConfig):
    """``[task]`` of the funnel alignment: the scenario's name only (its settings are
    ``[alignment]``)."""

    scenario: Literal["funnel_alignment"] = "funnel_alignment"


class FunnelAlignment(Scenario):
    """The funnel alignment's geometry and judges (truth, tracker, observer, settings)."""

    name = "funnel_alignment"
    label = "funnel alignment"
    config_model = FunnelTask
    tables = ("alignment",)
    goal = "funnels aligned"
    topics = (CdrTopic("/task/funnel", PLACEMENT, "every controller cycle with ground truth"),)

    @classmethod
    def create(cls, config: object, protocol: RunProtocol) -> FunnelAlignment:
        return cls(protocol.alignment)

    def __init__(self, alignment: Alignment) -> None:
        self.alignment = alignment
        self.source: Source | None = None
        self.truth_aligned: bool | None = None
        """The truth's verdict beside whoever judges (``None`` without ground truth)."""
        self.placement: Placement | None = None
        """The latest relative pose of tool and funnel the judge used (truth or tracker)."""
        a = alignment
        self.observer = WrenchObserver(ObserverLimits(
            seated_depth_m=a.seated_depth_m, lateral_force_n=a.lateral_force_n,
            lateral_torque_nm=a.lateral_torque_nm, wall_force_ratio=a.wall_force_ratio,
            min_force_n=a.min_force_n,
            lateral_speed_mps=a.lateral_speed_mps, yaw_rate_radps=math.radians(a.yaw_rate_dps),
            hold_s=a.observer_hold_s, target_mass_kg=a.target_mass_kg))
        self._start_z_axis = np.array([0.0, 0.0, 1.0])
        self._start_z = 0.0
        self._first_contact_z: float | None = None
        self._truth_since_ns: int | None = None
        self._tracker_seen = False
        self._target: TargetObservation | None = None
        self._truth_p: Placement | None = None
        """The truth's placement this cycle (``None``: no truth)."""
        self._within_of: Placement | None = None  # the placement last judged, and how
        self._geo = np.zeros(6)  # funnel_observe's output (kernels.GEO_*)
        # its tolerances (kernels.TOL_*)
        self._tol = np.array([a.lateral_tol_m, a.yaw_tol_deg, a.min_insertion_m])
        from ffexp.estimation import kernels as ek

        self._ekernels = ek
        self._est_rows = np.zeros(ek.OF_SIZE), np.zeros(ek.OI_SIZE, dtype=np.int64)
        self._want = alignment.source
        self._kernels = kernels()
        self._within_is = False
        # messages()' one message, filled in place each cycle (its record is encoded at once)
        self._record = _PlacementRecord(Placement((0.0, 0.0, 0.0, 0.0)), False)
        self._messages: list[tuple[str, object]] = [("/task/funnel", self._record)]

    @property
    def hold_s(self) -> float:
        return self.alignment.hold_s

    def start(self, state: RobotState) -> None:
        start_pose = state.tcp_pose_m.copy()
        self._start_z_axis = start_pose[:3, 2].copy()
        self._start_z = float(self._start_z_axis.dot(start_pose[:3, 3]))

    def _advance(self, state: RobotState) -> float:
        """The tool's travel along the start TCF's Z since the tare [m]."""
        return float(self._start_z_axis.dot(state.tcp_pose_m[:3, 3])) - self._start_z

    def _fresh(self, state: RobotState, target: TargetObservation | None) -> bool:
        if target is None or not target.valid:
            return False
        age_ns = state.time_ns - target.time_ns
        return age_ns <= self.alignment.tracker_max_age_s * NS_PER_S

    # -- who judges ----------------------------------------------------------
    def choose_source(self, state: RobotState,
                      target: TargetObservation | None) -> SourceChange | None:
        self._target = target
        if target is not None:
            self._tracker_seen = True
        want = self._want
        src: Source
        if want == "auto":
            if state.truth is not None:
                if self.source == "truth":  # as last cycle (the most common case)
                    return None
                src = "truth"
            elif self._tracker_seen:
                src = "tracker" if self._fresh(state, target) else "observer"
            else:
                src = "observer"
        elif want == "tracker":
            src = "tracker" if self._fresh(state, target) else "observer"
        else:
            src = want
        if src == self.source:
            return None
        old, self.source = self.source, src
        if old is None:
            return SourceChange(src, "INFO", f"{src} judges the alignment")
        if old == "tracker":
            if target is None or not target.valid:
                why = f"lost ({target.status})" if target is not None and target.status \
                    else "lost"
            else:
                why = "stale"
            return SourceChange(
                src, "WARNING", f"the tracker's pose is {why}: the observer judges until it "
                "returns")
        return SourceChange(src, "INFO", f"{src} judges the alignment again")

    # -- every cycle ---------------------------------------------------------
    def observe(self, t_ns: int, state: RobotState, est: Estimate,
                target: TargetObservation | None) -> None:
        truth = state.truth
        if truth is not None and self.truth_aligned is None:
            self.truth_aligned = False  # the truth is there: it says "not aligned" until held
        # truth_placement, _advance, the tolerances and the observer's cycle in one
        # compiled call (the same numbers; the functions themselves when a pose holds a NaN)
        tcp = state.tcp_pose_m
        mouth = None if truth is None else truth.sites.get(MOUTH_SITE)
        geo = self._geo
        obs = self.observer
        ostate = obs.state
        ef, ei = est.floats, est.ints
        if ef is None or ei is None:  # an estimate not made by the estimator: its rows
            ef, ei = self._rows(est)
        if mouth is None:
            self._truth_p = None
            if self._kernels.funnel_observe(tcp, tcp, tcp, self._start_z_axis, False,
                                            self._start_z, self._tol, geo, ef, ei, t_ns,
                                            ostate.floats, ostate.ints, obs.lims):
                self._place(state)
                return
            z = self._advance(state)
        else:
            assert truth is not None
            if self._kernels.funnel_observe(truth.sites.get(TCP_SITE, tcp), mouth, tcp,
                                            self._start_z_axis, True, self._start_z,
                                            self._tol, geo, ef, ei, t_ns,
                                            ostate.floats, ostate.ints, obs.lims):
                x, y, v, yaw, _, within = geo.tolist()
                p = self._truth_p = Placement((x, y, v, yaw))
                self._within_of, self._within_is = p, within == 1.0
                if self.source == "truth":  # _place, inline
                    self.placement = p
                else:
                    self._place(state)
                return
            self._truth_p = truth_placement(truth, tcp)
            z = self._advance(state)
        self._place(state)
        if est.in_contact:
            self.observer.contact_made(z)
        _, f_y, _, t_x, _, _ = est.wrench.tolist()
        _, v_y, _, w_x, _, _ = est.twist_tcf.tolist()
        self.observer.update(t_ns, z, est.in_contact, est.f_z, f_y, t_x, v_y, w_x)

    def _rows(self, est: Estimate) -> tuple[np.ndarray, np.ndarray]:
        """The estimator's output rows (its kernels' ``OF_*``, ``OI_*``) of ``est``."""
        ek = self._ekernels
        f, i = self._est_rows
        f[ek.OF_WRENCH:ek.OF_WRENCH + 6] = est.wrench
        f[ek.OF_TWIST:ek.OF_TWIST + 6] = est.twist_tcf
        f[ek.OF_FZ] = est.f_z
        i[ek.OI_IN_CONTACT] = est.in_contact
        return f, i

    def contact(self, state: RobotState) -> None:
        if self._first_contact_z is None:
            self._first_contact_z = self._advance(state)

    def contact_lost(self) -> None:
        self._truth_since_ns = None

    def _within(self, p: Placement) -> bool:
        """:meth:`Alignment.within`, asked once per placement (truth's: up to three
        times a cycle)."""
        if p is not self._within_of:
            self._within_of, self._within_is = p, self.alignment.within(p)
        return self._within_is

    def _shadow_truth(self, t_ns: int, state: RobotState) -> None:
        p = self._truth_p
        if p is not None:
            self._truth_holds(t_ns, self._within(p))

    def _truth_holds(self, t_ns: int, within: bool) -> None:
        """The truth's own hold, its placement this cycle ``within`` the tolerances or not."""
        if self.truth_aligned is None:
            self.truth_aligned = False
        if not within:
            self._truth_since_ns = None
            return
        if self._truth_since_ns is None:
            self._truth_since_ns = t_ns
        if t_ns - self._truth_since_ns >= self.alignment.hold_s * NS_PER_S:
            self.truth_aligned = True

    def truth_label(self) -> str:
        """The truth's verdict: held within tolerance for ``hold_s``, or within it when
        the run ended (another judge may end the run before the truth's own hold)."""
        if self.truth_aligned is None:
            return ""
        within = self._truth_since_ns is not None
        return "aligned" if self.truth_aligned or within else "not aligned"

    def _place(self, state: RobotState) -> None:
        """The relative pose of tool and funnel the judging source sees (truth, tracker)."""
        src = self.source
        if src == "truth":
            self.placement = self._truth_p
        elif src == "tracker":
            target = self._target
            self.placement = (None if target is None
                              else placement(state.tcp_pose_m, target.mouth_m))

    def messages(self) -> list[tuple[str, object]]:
        """``/task/funnel``'s message of this cycle: one list and record, filled again
        each cycle (encode it before the next)."""
        p = self._truth_p
        if p is None:
            return []
        self._record.fill(p, self._within(p))
        return self._messages

    # -- the verdict ---------------------------------------------------------
    def holds(self, t_ns: int, state: RobotState, est: Estimate,
              target: TargetObservation | None) -> bool:
        p = self._truth_p
        if p is not None and p is self._within_of and self.source == "truth":
            # the truth judges, its placement judged this cycle (observe's compiled call):
            # _shadow_truth and aligned_now in one
            within = self._within_is
            self.placement = p
            self._truth_holds(t_ns, within)
            return within
        self._shadow_truth(t_ns, state)
        return self.aligned_now(state, est)

    def aligned_now(self, state: RobotState, est: Estimate) -> bool:
        """This cycle's verdict of the judging source, before the hold time."""
        src = self.source
        if src in ("truth", "tracker"):
            self._place(state)
            return self.placement is not None and self._within(self.placement)
        if src == "settings":
            if self._first_contact_z is None:
                return False
            advanced = self._advance(state) - self._first_contact_z
            a = self.alignment
            return advanced >= a.seated_depth_m and abs(float(est.wrench[1])) <= a.lateral_force_n
        # the observer holds its own evidence for observer_hold_s; the task's hold adds to it
        return self.observer.state.label == "aligned"

    def final(self, reached: bool) -> Verdict:
        src = self.source or "observer"
        truth = self.truth_label()
        if src == "observer":
            obs = self.observer.state
            label = "aligned" if reached else self.observer.final()
            if label == "aligned" and not reached:
                label = "unverified"  # seen aligned, but the run ended before the hold
            reason = {"aligned": "robot-side evidence of seated cones held",
                      "not aligned": "the tool rests on one wall of the funnel, or is "
                                     "out of contact behind where it first touched",
                      "unverified": "the robot alone cannot tell where the target is"}[label]
            return Verdict(label, src, reason, dict(obs.evidence), truth, True)
        label = "aligned" if reached else "not aligned"
        evidence: dict[str, float] = {}
        p = self.placement
        if p is not None:
            evidence = {"insertion_m": p.insertion, "lateral_m": p.lateral,
                        "vertical_m": p.vertical, "yaw_deg": math.degrees(p.yaw)}
        hold = self.alignment.hold_s
        reason = (f"{src}: relative pose within tolerance for {hold} s" if reached
                  else f"{src}: never within tolerance for {hold} s")
        return Verdict(label, src, reason, evidence, truth, True)
