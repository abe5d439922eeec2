from __future__ import annotations

from pathlib import Path

import pytest

from drivers.description.scene import Scene, load_scene
from drivers.errors import ConfigError


def test_paper_scene_is_the_default_rig(paper_scene: Scene) -> None:
    assert paper_scene.model_dump() == Scene().model_dump()
    assert paper_scene.substeps == 5
    assert paper_scene.ft_decimation == 1


def test_unknown_key_names_file_and_field(tmp_path: Path) -> None:
    p = tmp_path / "s.toml"
    p.write_text("[target]\nmass = 12.0\ncolour = 'red'\n")
    with pytest.raises(ConfigError) as exc:
        load_scene(p)
    assert str(exc.value) == f"{p}: target.colour: unknown key"


def test_bed_friction_limited_to_paper_range(tmp_path: Path) -> None:
    p = tmp_path / "s.toml"
    p.write_text("[target]\nmu = 0.05\n")
    with pytest.raises(ConfigError, match=r"target\.mu"):
        load_scene(p)


def test_fri_cycle_must_be_multiple_of_timestep(paper_scene_path: Path) -> None:
    with pytest.raises(ConfigError, match="not a multiple"):
        load_scene(paper_scene_path, ["fri.cycle=0.0055"])


def test_fri_cycle_range_1_to_100_ms(paper_scene_path: Path) -> None:
    assert load_scene(paper_scene_path, ["fri.cycle=0.1"]).substeps == 100
    with pytest.raises(ConfigError, match=r"fri\.cycle"):
        load_scene(paper_scene_path, ["fri.cycle=0.2"])


def test_stiffness_above_max_rejected(paper_scene_path: Path) -> None:
    with pytest.raises(ConfigError, match="outside"):
        load_scene(paper_scene_path, ["controller.cart_stiffness=[6000,0,0,0,300,300]"])


def test_explicit_friction_overrides_scale(paper_scene_path: Path) -> None:
    s = load_scene(paper_scene_path, ["arm.coulomb=[1,2,3,4,5,6,7]"])
    assert s.arm.coulomb_friction() == [1, 2, 3, 4, 5, 6, 7]
    # viscous friction still comes from the scale times Jubien's 14.4 N m s/rad (A1)
    assert s.arm.viscous_friction()[0] == pytest.approx(s.arm.friction_scale * 14.4)
