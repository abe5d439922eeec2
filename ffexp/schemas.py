"""JSON Schemas of the configuration files, generated from their pydantic models.

``ffexp schema KIND`` prints one; ``schemas/*.json`` in the repository are
these texts (``tests/test_schema.py`` checks they are current;
``ffexp schema --write schemas`` regenerates them). Protocol, rig and scene
files point editors at them with a first line such as
``#:schema ../schemas/protocol.json`` (Taplo / Even Better TOML), so an
editor completes field names and flags unknown fields and wrong types.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ffexp.errors import InputError

DIALECT = "https://json-schema.org/draft/2020-12/schema"


def _run_protocol() -> type[Any]:
    from ffexp.protocol import RunProtocol

    return RunProtocol


def _campaign() -> type[Any]:
    from ffexp.protocol import CampaignProtocol

    return CampaignProtocol


def _sec3_sweep() -> type[Any]:
    from ffexp.contact1dof.sweep import SweepProtocol

    return SweepProtocol


def _scene() -> type[Any]:
    from drivers.description.scene import Scene

    return Scene


def _rig() -> type[Any]:
    from drivers.rig import Rig

    return Rig


def _hil_impact() -> type[Any]:
    from ffexp.hil.protocol import HilProtocol

    return HilProtocol


def _study() -> type[Any]:
    from ffexp.sweeps.reproduce import ReproduceConfig

    return ReproduceConfig


#: kind -> (the model, what its files are). The file is ``schemas/<kind>.json``.
KINDS: dict[str, tuple[Callable[[], type[Any]], str]] = {
    "protocol": (_run_protocol, "a run protocol (protocols/method*.toml)"),
    "campaign": (_campaign, "a campaign (protocols/paper.toml)"),
    "sec3-sweep": (_sec3_sweep, "a Section III sweep (protocols/sec3_*.toml)"),
    "scene": (_scene, "a simulated scene (data/scenes/*.toml)"),
    "rig": (_rig, "a rig (rigs/*.toml)"),
    "study": (_study, "a study of the paper's claims (protocols/reproduce.toml, robustness*.toml)"),
    "hil-impact": (_hil_impact, "an impact on a rendered target (protocols/hil_impact.toml)"),
}


def schema_text(kind: str) -> str:
    """The JSON Schema of ``kind`` as indented JSON text, ending in a newline."""
    if kind not in KINDS:
        raise InputError(f"schema: {kind!r} is not a kind; choose one of {', '.join(KINDS)}")
    model_of, what = KINDS[kind]
    schema: dict[str, Any] = {"$schema": DIALECT, **model_of().model_json_schema()}
    schema.setdefault("description", f"ffexp: {what}.")
    return json.dumps(schema, indent=2, sort_keys=False) + "\n"


def write_all(out_dir: Path) -> list[Path]:
    """Write every kind as ``out_dir/<kind>.json``; return the paths."""
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        paths = []
        for kind in KINDS:
            path = out_dir / f"{kind}.json"
            path.write_text(schema_text(kind))
            paths.append(path)
    except OSError as exc:
        raise InputError(f"{exc.filename or out_dir}: cannot write: {exc.strerror}") from None
    return paths
