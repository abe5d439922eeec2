"""The rig in 3-D for Foxglove: simple shapes from the scene file moving with the run.

:mod:`~ffexp.scene3d.kinematics` is the scene's arm's forward kinematics (pure),
:mod:`~ffexp.scene3d.entities` the ``foxglove.SceneUpdate`` of the rig (pure),
:mod:`~ffexp.scene3d.writer` the :class:`~ffexp.runlog.RunLog` sink that
writes both to the recording (and so to the live server).
"""

from __future__ import annotations

from ffexp.scene3d.writer import SCENE_TOPIC, SceneWriter

__all__ = ["SCENE_TOPIC", "SceneWriter"]
