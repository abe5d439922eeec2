"""Which kind of ffexp file a TOML table is (ffexp/filekind.py): every shipped file is
recognised as what it is, and a file loaded as another kind says which it is."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from ffexp.campaign import CampaignProtocol
from ffexp.errors import ConfigError
from ffexp.filekind import kind_of, load_as, wrong_kind
from ffexp.hil.protocol import HilProtocol

ROOT = Path(__file__).resolve().parents[1]


def _expected(path: Path) -> str:
    name = path.stem
    if path.parent.name == "rigs":
        return "rig"
    if path.parent.name == "scenes":
        return "scene"
    if name in ("paper", "sixdof"):
        return "campaign"
    if name == "reproduce" or name.startswith("robustness"):
        return "study"
    if name.startswith("hil_"):
        return "impact protocol"
    if name.startswith("sec3_"):
        return "sweep protocol"
    return "run protocol"


SHIPPED = sorted([*ROOT.glob("protocols/*.toml"), *ROOT.glob("rigs/*.toml"),
                  *ROOT.glob("data/scenes/*.toml")])


@pytest.mark.parametrize("path", SHIPPED, ids=[str(p.relative_to(ROOT)) for p in SHIPPED])
def test_every_shipped_file_is_recognised(path: Path) -> None:
    with path.open("rb") as fh:
        data = tomllib.load(fh)
    assert kind_of(data) == _expected(path)
    assert wrong_kind(data, _expected(path)) is None


def test_runs_by_role_are_a_study_and_a_list_of_runs_a_campaign() -> None:
    assert kind_of({"name": "x", "runs": {"m1": {"protocol": "a.toml"}}}) == "study"
    assert kind_of({"name": "x", "runs": [{"protocol": "a.toml"}]}) == "campaign"
    # a study's own keys with no runs at all
    assert kind_of({"name": "x", "claims": {}}) == "study"


def test_the_article_follows_the_kind() -> None:
    data = {"impact": {"speed_mps": 0.05}, "scene": "s.toml"}
    assert wrong_kind(data, "run protocol") == \
        "is an impact protocol, not a run protocol (use it as ffexp hil FILE)"
    assert wrong_kind({"robot": {}}, "impact protocol") == \
        "is a rig, not an impact protocol (use it as --rig FILE)"


def test_load_as_names_the_kind_or_keeps_the_field_error(tmp_path: Path) -> None:
    with pytest.raises(ConfigError) as exc:
        load_as(HilProtocol, ROOT / "protocols/method2.toml", (), "impact protocol")
    assert str(exc.value).endswith(
        "method2.toml: is a run protocol, not an impact protocol (use it as ffexp run FILE)")
    # the right kind with a bad value: the field's own error, not a kind
    with pytest.raises(ConfigError) as exc:
        load_as(HilProtocol, ROOT / "protocols/hil_impact.toml", ("impact.speed_mps=x",),
                "impact protocol")
    assert "impact.speed_mps" in str(exc.value)
    # a file of no kind at all keeps its validation error
    odd = tmp_path / "odd.toml"
    odd.write_text('colour = "red"\n')
    with pytest.raises(ConfigError) as exc:
        load_as(CampaignProtocol, odd, (), "campaign")
    assert "odd.toml: name: Field required" in str(exc.value) and " is a" not in str(exc.value)
    # and a good file loads
    assert load_as(HilProtocol, ROOT / "protocols/hil_impact.toml", (), "impact protocol")
