"""Experiment protocols (TOML -> pydantic): one run of the paper, and campaigns.

A run protocol names the method, the scene it runs in (simulator) and every
number of the experiment; the defaults are the paper's (Table exp_table:
approach impedance Z 500 N/m, damping 1; PI gains k_zp 1, k_zi 0.07).
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from pydantic import Field, ValidationError, field_validator, model_validator
from pydantic_core import PydanticCustomError

from drivers.config import (
    StrictModel,
    Vec6,
    apply_overrides,
    parse_override,
    read_toml,
    validate,
)
from ffexp import scenarios
from ffexp.controllers import REGISTRY, AlignConfig
from ffexp.controllers.force import ForceRiConfig
from ffexp.controllers.laws import ImpedanceConfig
from ffexp.errors import ConfigError
from ffexp.estimation import Estimation
from ffexp.filekind import wrong_kind
from ffexp.outcome import ALIASES, OUTCOMES
from ffexp.safety import Limits
from ffexp.scenarios import TaskConfig
from ffexp.scenarios.funnel import Alignment, FunnelTask


class SceneRef(StrictModel):
    """The simulated rig: a scene file (relative to the protocol) and overrides."""

    file: str = "../data/scenes/paper.toml"
    set: list[str] = Field(default_factory=list, description="dotted.key=value overrides")


class KrcSettings(StrictModel):
    """The robot's own Cartesian impedance during the experiment (on the KRC: FRI).

    The paper sets X, rot-Y, rot-Z to maximal stiffness (gravity plane held)
    and Y, Z, rot-X to zero, and applies its controller through addTcpFT.
    Order ``[x, y, z, rx, ry, rz]`` in TCF.
    """

    cart_stiffness: Vec6 = (5000.0, 0.0, 0.0, 0.0, 300.0, 300.0)
    cart_damping: Vec6 = (0.7, 0.0, 0.0, 0.0, 0.7, 0.7)
    hold_stiffness: Vec6 = Field(
        (2000.0, 2000.0, 2000.0, 200.0, 200.0, 200.0),
        description="Stiffness of the safe stop: hold the pose on every axis.",
    )
    hold_damping: Vec6 = (0.7, 0.7, 0.7, 0.7, 0.7, 0.7)


class RunSettings(StrictModel):
    """Timing of the run."""

    timeout_s: float = Field(30.0, gt=0, description="Simulated/robot time for the whole run.")
    tare_s: float = Field(
        0.25, gt=0, description="Free-space sensor time the tare averages (any sensor rate)."
    )
    stop_hold_s: float = Field(0.1, ge=0, description="Safe-stop hold after DONE/ABORT.")
    stop_ramp_s: float = Field(
        0.05, ge=0,
        description="The safe stop ramps from the last command (gains and wrench) to the hold "
                    "stiffness, hold damping and zero wrench over this time (0: one step; cut "
                    "at the end of stop_hold_s).")
    resume_ramp_s: float = Field(
        0.05, ge=0,
        description="After the robot stopped commanding for a few cycles in ALIGN and came "
                    "back, the method's wrench is blended in from the held one over this time.")
    tf_period_s: float = Field(0.02, gt=0, description="Period of /tf transforms in the log.")
    end_on_aligned: bool = Field(
        True, description="End the run (DONE) once the funnels have been aligned for "
                          "alignment.hold_s. false: a momentary seat is noted (an 'aligned' "
                          "event) and the run goes on to timeout_s, so contact that keeps "
                          "breaking afterwards is seen (the paper's Method III ran to 48 s).")


class RunProtocol(StrictModel):
    """One experiment: ``protocols/method*.toml``.

    ``[align] method = "..."`` picks the ALIGN-phase method from the registry
    (:mod:`ffexp.controllers`); the rest of ``[align]`` is that method's
    settings. A file of the earlier form (``method`` at the top) is read as if
    ``method`` were in ``[align]``; so is ``--set method=...``.
    ``[task] scenario = "..."`` picks the scenario, the task's goal and its
    judges, from its registry (:mod:`ffexp.scenarios`) the same way; the
    default, ``"funnel_alignment"``, takes its settings from ``[alignment]``.
    """

    name: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_.-]+$")
    description: str = ""
    seed: int = Field(0, ge=0, description="The run's random seed (non-negative).")
    scene: SceneRef = SceneRef()
    run: RunSettings = RunSettings()
    approach: ImpedanceConfig = ImpedanceConfig()
    align: AlignConfig = Field(default_factory=ForceRiConfig)
    krc: KrcSettings = KrcSettings()
    estimation: Estimation = Estimation()
    limits: Limits = Limits()
    task: TaskConfig = Field(
        FunnelTask(), exclude_if=scenarios.is_default,
        description="The scenario (its goal and judges): scenario = one of the registry "
                    "(ffexp.scenarios), the rest its own settings.")
    alignment: Alignment = Field(
        Alignment(),
        description="The funnel_alignment scenario's settings (tolerances and judges).")
    paper: dict[str, float | str] = Field(
        default_factory=dict,
        description="The paper's reported values for this run (Table res_par), for comparison; "
                    f"outcome: one of {', '.join(OUTCOMES)} (ffexp.outcome).",
    )

    @field_validator("paper")
    @classmethod
    def _paper_outcome(cls, paper: dict[str, float | str]) -> dict[str, float | str]:
        outcome = paper.get("outcome")
        if outcome is not None and outcome not in OUTCOMES and outcome not in ALIASES:
            raise ValueError(f"outcome {outcome!r} is not one of {', '.join(OUTCOMES)}")
        return paper

    @model_validator(mode="after")
    def _tables_of_the_scenario(self) -> RunProtocol:
        """A table only another scenario reads is an error unless it says nothing (a dump
        of the protocol has every table, with its defaults)."""
        name = self.task.scenario
        for table in sorted(scenarios.other_tables(name) & self.model_fields_set):
            if getattr(self, table) != type(self).model_fields[table].get_default(
                    call_default_factory=True):
                error = PydanticCustomError(
                    "other_scenario", "scenario {name} does not read this table; its settings "
                    "go in [task]", {"name": repr(name)})
                raise ValidationError.from_exception_data(
                    "RunProtocol", [{"type": error, "loc": (table,), "input": None}])
        return self

    @model_validator(mode="before")
    @classmethod
    def _method_into_align(cls, data: Any) -> Any:
        if isinstance(data, dict) and "method" in data:
            data = dict(data)
            method = data.pop("method")
            align = data.get("align", {})
            if isinstance(align, dict):  # the top-level key (or --set method=...) wins
                data["align"] = {**align, "method": method}
        return data

    @property
    def method(self) -> str:
        """The ALIGN-phase method's registry name."""
        return self.align.method

    @property
    def scenario(self) -> str:
        """The scenario's registry name."""
        return self.task.scenario


class CampaignEntry(StrictModel):
    protocol: str
    set: list[str] = Field(default_factory=list)


class CampaignProtocol(StrictModel):
    """Several runs compared side by side: ``protocols/paper.toml``."""

    name: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_.-]+$")
    description: str = ""
    runs: list[CampaignEntry] = Field(min_length=1)


#: Keys under ``[scene]`` that are the protocol's own; any other ``scene.KEY`` is a scene key.
SCENE_FIELDS = ("file", "set")


def split_scene_overrides(overrides: Iterable[str]) -> tuple[list[str], list[str]]:
    """``--set`` overrides as (the protocol's, the scene's): ``scene.target.lateral=0.012``
    is the scene's ``target.lateral=0.012`` (an entry of ``[scene] set``); ``scene.file``
    and ``scene.set`` stay the protocol's."""
    own: list[str] = []
    scene: list[str] = []
    for text in overrides:
        key = text.partition("=")[0].strip()
        parts = key.split(".")
        if len(parts) >= 2 and parts[0] == "scene" and parts[1] not in SCENE_FIELDS:
            scene.append(text.strip()[len("scene."):])
        else:
            own.append(text)
    return own, scene


def with_scene_overrides(data: dict[str, Any], scene: Sequence[str]) -> dict[str, Any]:
    """``data`` (a run protocol's TOML) with ``scene`` appended to its ``[scene] set``."""
    if not scene:
        return data
    table = data.get("scene")
    table = dict(table) if isinstance(table, dict) else {}
    before = table.get("set", [])
    table["set"] = [*(before if isinstance(before, list) else [before]), *scene]
    return {**data, "scene": table}


_ELEMENT = re.compile(r"^\s*(?P<key>[A-Za-z_][\w.]*)\[(?P<index>\d+)\]\s*=(?P<value>.*)$")


def _apply(data: dict[str, Any], overrides: Sequence[str]) -> dict[str, Any]:
    """``data`` with the overrides applied in order; ``key[i]=value`` replaces one element
    of a list (``align.k_ri[3]=1.0``), as a sweep's keys do."""
    for text in overrides:
        m = _ELEMENT.match(text)
        if m is None:
            data = apply_overrides(data, [text])
            continue
        path, value = parse_override(f"{m['key']}={m['value']}")
        node: Any = data
        for part in path:
            node = node.get(part) if isinstance(node, dict) else None
        if not isinstance(node, list):  # a field the file leaves at its default
            node = validate(RunProtocol, data, "--set").model_dump(mode="json")
            for part in path:
                node = node.get(part) if isinstance(node, dict) else None
        index = int(m["index"])
        if not isinstance(node, list) or index >= len(node):
            raise ConfigError("--set", text, f"{'.'.join(path)} has no element {index}"
                              if isinstance(node, list) else f"{'.'.join(path)} is not a list")
        element = list(node)
        element[index] = value
        data = apply_overrides(data, [f"{'.'.join(path)}={json.dumps(element)}"])
    return data


def load_run_protocol(path: Path, overrides: list[str] | tuple[str, ...] = ()) -> RunProtocol:
    """Read a run protocol with ``--set`` overrides (one-line errors naming the field as
    written in the file: ``align.k_ri``, not pydantic's ``align.force.k_ri``); a scene
    key is overridden as ``scene.target.lateral=0.012`` (:func:`split_scene_overrides`)."""
    raw = read_toml(path)
    try:
        return run_protocol_from(raw, overrides, str(path))
    except ConfigError:
        what = wrong_kind(raw, "run protocol")
        if what is not None:
            raise ConfigError(str(path), "", what) from None
        raise


def run_protocol_from(data: dict[str, Any], overrides: Sequence[str],
                      source: str) -> RunProtocol:
    """A run protocol from its table (a file's, a recording's) with ``--set`` overrides,
    as :func:`load_run_protocol` takes them (scene keys, list elements); errors name
    ``source`` and the field as written (``align.k_ri``, not ``align.force.k_ri``)."""
    own, scene = split_scene_overrides(overrides)
    try:
        return validate(RunProtocol, with_scene_overrides(_apply(data, own), scene), source)
    except ConfigError as exc:
        parts = exc.field.split(".")
        if len(parts) >= 2 and parts[0] == "align" and parts[1] in REGISTRY:
            del parts[1]
            raise ConfigError(exc.source, ".".join(parts), exc.message) from None
        raise


def scene_path(protocol_path: Path, protocol: RunProtocol) -> Path:
    """The scene file, relative to the protocol file's folder."""
    p = Path(protocol.scene.file)
    return p if p.is_absolute() else (protocol_path.parent / p)
