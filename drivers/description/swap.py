"""A scene for a robot that puts its own arm in the place of a scene's other arm."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from drivers.description.arm import ArmDescription
from drivers.description.scene import Scene, load_scene


def scene_with_arm(path: Path, overrides: Sequence[str], arm: ArmDescription,
                   paper_overrides: Sequence[str]) -> Scene:
    """The scene at ``path`` with ``overrides``; when it holds another arm than ``arm`` (a
    protocol's scene of the paper's rig), the same scene with ``arm`` put in its place by
    ``paper_overrides`` first (the arm's own mount, start pose and controller), so that
    the command line's overrides still come last."""
    scene = load_scene(path, list(overrides))
    if scene.arm.description is not arm:
        scene = load_scene(path, [*paper_overrides, *overrides])
    return scene
