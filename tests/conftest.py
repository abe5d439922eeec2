"""Shared fixtures for the simulator and driver tests."""

from __future__ import annotations

from pathlib import Path

import pytest

from drivers.description.scene import Scene, load_scene

PAPER_SCENE = Path(__file__).resolve().parent.parent / "data" / "scenes" / "paper.toml"


@pytest.fixture(scope="session")
def paper_scene_path() -> Path:
    return PAPER_SCENE


@pytest.fixture(scope="session")
def paper_scene() -> Scene:
    return load_scene(PAPER_SCENE)
