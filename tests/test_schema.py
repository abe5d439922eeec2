"""JSON Schemas of the configuration files: current, pointed at, and checking.

``schemas/*.json`` must equal what ``ffexp schema KIND`` prints from the
pydantic models today (regenerate with ``ffexp schema --write schemas``);
every protocol and rig file names its schema on its first line (Taplo's
``#:schema`` directive), and each file validates against it.
"""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import pytest
from typer.testing import CliRunner

from ffexp.cli import app
from ffexp.schemas import KINDS, schema_text

ROOT = Path(__file__).resolve().parents[1]
runner = CliRunner()


@pytest.mark.parametrize("kind", list(KINDS))
def test_repository_schema_is_current(kind: str) -> None:
    path = ROOT / "schemas" / f"{kind}.json"
    assert path.read_text() == schema_text(kind), (
        f"{path} is stale: run `ffexp schema --write schemas`"
    )


def test_cli_prints_the_schema() -> None:
    result = runner.invoke(app, ["schema", "protocol"])
    assert result.exit_code == 0, result.stderr
    schema = json.loads(result.stdout)
    assert schema["$schema"].endswith("2020-12/schema")
    assert schema["additionalProperties"] is False  # unknown fields are errors, as in ffexp
    assert {"name", "align", "run", "seed"} <= set(schema["properties"])


def pointed_files() -> list[Path]:
    return sorted((ROOT / "protocols").glob("*.toml")) + sorted((ROOT / "rigs").glob("*.toml"))


@pytest.mark.parametrize("path", pointed_files(), ids=lambda p: f"{p.parent.name}/{p.name}")
def test_file_points_at_its_schema_and_validates(path: Path) -> None:
    jsonschema = pytest.importorskip("jsonschema")
    first = path.read_text().splitlines()[0]
    assert first.startswith("#:schema ../schemas/"), f"{path}: first line {first!r}"
    schema_path = (path.parent / first.removeprefix("#:schema ").strip()).resolve()
    schema = json.loads(schema_path.read_text())
    data = tomllib.loads(path.read_text())
    jsonschema.validate(data, schema)


@pytest.mark.parametrize(
    ("kind", "bad"),
    [
        ("protocol", {"name": "x", "colour": 1}),
        ("protocol", {"name": "x", "seed": "one"}),
        ("campaign", {"name": "c", "runs": []}),
        ("rig", {"robot": {"type": "warp"}}),
        ("sec3-sweep", {"name": "s", "sweep": {"parameter": "colour", "values": [1]}}),
        ("study", {"name": "s", "seeds": []}),
    ],
)
def test_schema_rejects_what_the_model_rejects(kind: str, bad: dict[str, object]) -> None:
    jsonschema = pytest.importorskip("jsonschema")
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(bad, json.loads(schema_text(kind)))
