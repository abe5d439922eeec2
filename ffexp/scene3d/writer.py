"""The 3-D scene writer: a :class:`~ffexp.runlog.RunLog` sink (``RunLog.sinks``).

At the first cycle it places the scene (:func:`drivers.description.layout.compute_layout`
from the measured start TCF, as the simulator does) and picks the target's
frame: ``target`` (ground truth, which the run log puts on ``/tf``) when the
robot reports it, else ``target_tracked`` (the tracker's, also the run log's)
when the rig has a tracker, else ``target_nominal``, the start placement of
the scene, written here (with both truth and a tracker, the tracker's target
is drawn too, as a ghost). Then it writes

- ``/scene/rig`` (:func:`ffexp.scene3d.entities.scene_update`) at the start
  and every ``scene_period_s`` of log time;
- ``/tf``: ``link1`` .. ``link{n}`` of the scene's arm from the joint
  positions by forward kinematics (:mod:`ffexp.scene3d.kinematics`), each in
  its parent (:class:`~ffexp.scene3d.linktf.LinkTransforms`), every ``tf_period_s``
  (the run log's ``/tf`` period), when the
  robot reports as many joints as that arm has.
"""

from __future__ import annotations

import numpy as np

from drivers.base.types import NS_PER_S, RobotState, TargetObservation
from drivers.description import Layout, Scene, compute_layout
from ffexp.recording import Recorder
from ffexp.recording.topics.target import TRACKED_FRAME
from ffexp.scene3d.entities import scene_update
from ffexp.scene3d.kinematics import base_pose, link_frames, translation
from ffexp.scene3d.linktf import LinkTransforms

__all__ = ["NOMINAL_FRAME", "SCENE_TOPIC", "TRUTH_FRAME", "SceneWriter"]

SCENE_TOPIC = "/scene/rig"
#: ``/tf`` frame of the simulator's target (written by the run log).
TRUTH_FRAME = "target"
#: ``/tf`` frame of the target's start placement when nothing observes it.
NOMINAL_FRAME = "target_nominal"


class SceneWriter:
    """Writes the rig's 3-D scene beside a run's topics.

    Args:
        rec: the run's recording.
        scene: the rig's scene (the protocol's, or the sim rig's own).
        tf_period_s: period of the links' ``/tf``.
        scene_period_s: period of ``/scene/rig`` after the first.
    """

    def __init__(self, rec: Recorder, scene: Scene, tf_period_s: float,
                 scene_period_s: float = 1.0) -> None:
        self.rec = rec
        self.scene = scene
        self.tf_period_ns = max(1, round(tf_period_s * NS_PER_S))
        self.scene_period_ns = max(1, round(scene_period_s * NS_PER_S))
        self.base = base_pose(scene)
        self.arm = scene.arm.description
        self.frames = link_frames(self.arm)
        self.links = LinkTransforms(self.arm, self.base, self.frames, rec.encode_transform)
        self.layout: Layout | None = None
        self.target_frame = ""
        self.tracked_frame = ""
        self._next_tf_ns = 0
        self._next_scene_ns = 0
        self._nominal = np.eye(4)

    def _start(self, state: RobotState, target: TargetObservation | None) -> Layout:
        pose = state.tcp_pose_m
        layout = compute_layout(self.scene, pose[:3, 3].copy(), pose[:3, :3].copy())
        if state.truth is not None:
            self.target_frame = TRUTH_FRAME
            self.tracked_frame = TRACKED_FRAME if target is not None else ""
        elif target is not None:
            self.target_frame = TRACKED_FRAME
        else:
            self.target_frame = NOMINAL_FRAME
            self._nominal = translation(*layout.target_pos)
            self._nominal[:3, :3] = layout.target_rot
        return layout

    def cycle(self, log_ns: int, state: RobotState, target: TargetObservation | None,
              out: list[tuple[str, bytes]] | None = None) -> None:
        """One cycle at log time ``log_ns``: the scene and the links' transforms when due,
        appended to ``out`` (written by the caller) when given, else written."""
        layout = self.layout
        if layout is None:
            layout = self.layout = self._start(state, target)
        q = state.joint_pos_rad
        tf_due = log_ns >= self._next_tf_ns and len(q) == self.arm.joints
        if log_ns < self._next_scene_ns and not tf_due:
            return  # nothing due this cycle
        rec = self.rec
        msgs: list[tuple[str, bytes]] = [] if out is None else out
        if log_ns >= self._next_scene_ns:
            self._next_scene_ns = log_ns + self.scene_period_ns
            msg = scene_update(self.scene, layout, log_ns, self.target_frame, self.base,
                               self.tracked_frame)
            msgs.append((SCENE_TOPIC, rec.encode_json(msg)))
            if self.target_frame == NOMINAL_FRAME:
                msgs.append(("/tf", rec.encode_transform(log_ns, "base", NOMINAL_FRAME,
                                                         self._nominal.tolist())))
        if tf_due:
            self._next_tf_ns = log_ns + self.tf_period_ns
            msgs.extend([("/tf", data) for data in self.links.messages(log_ns, q)])
        if out is None and msgs:
            rec.write_batch(log_ns, msgs)
