"""The registry of scenarios: the paper's funnel alignment and more.

A protocol picks one with ``[task] scenario = "..."`` (``"funnel_alignment"``
when it does not say); the rest of ``[task]`` is that scenario's config model
(:attr:`Scenario.config_model <ffexp.scenarios.base.Scenario>`), validated by
pydantic so errors name the scenario's own fields (``task.force_band_n``). The
funnel alignment keeps its settings in ``[alignment]``, where they always
were. To add a scenario: write one module with a
:class:`~ffexp.scenarios.base.Scenario` subclass and its config model
(``scenario: Literal["name"]``), and list the class in :data:`_SCENARIOS`
below (or :func:`register` it, as a test does). Nothing else in ffexp names a
scenario; ``schemas/protocol.json`` is generated from this registry.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Annotated, Any

from pydantic import GetJsonSchemaHandler, SerializeAsAny, ValidationError, WrapValidator
from pydantic.json_schema import JsonSchemaValue
from pydantic_core import PydanticCustomError, core_schema

from drivers.base.topics import CdrTopic
from ffexp.scenarios.base import Scenario, ScenarioConfig, SourceChange, Verdict
from ffexp.scenarios.docking6 import Docking6
from ffexp.scenarios.funnel import FunnelAlignment, FunnelTask

if TYPE_CHECKING:
    from ffexp.protocol import RunProtocol

_SCENARIOS: tuple[type[Scenario], ...] = (FunnelAlignment, Docking6)

DEFAULT = FunnelAlignment.name
"""The scenario of a protocol that names none."""

#: scenario name -> scenario class
REGISTRY: dict[str, type[Scenario]] = {cls.name: cls for cls in _SCENARIOS}


_listeners: list[Callable[[], None]] = []


def register(cls: type[Scenario]) -> type[Scenario]:
    """Add a scenario to the registry (usable as a class decorator); a name that is taken
    by another class is a ``ValueError``."""
    known = REGISTRY.get(cls.name)
    if known is not None and known is not cls:
        raise ValueError(f"scenario {cls.name!r} is already registered ({known.__qualname__})")
    REGISTRY[cls.name] = cls
    for callback in _listeners:
        callback()
    return cls


def on_change(callback: Callable[[], None]) -> None:
    """Call ``callback()`` whenever :func:`register` changed the registry (the recording's
    topics follow it)."""
    _listeners.append(callback)


def scenario_topics() -> tuple[CdrTopic, ...]:
    """The recording topics every registered scenario declares."""
    return tuple(t for cls in REGISTRY.values() for t in cls.topics)


def scenario_class(name: str) -> type[Scenario]:
    """The scenario registered as ``name`` (KeyError names the known ones)."""
    try:
        return REGISTRY[name]
    except KeyError:
        raise KeyError(f"unknown scenario {name!r}; known: {', '.join(REGISTRY)}") from None


def label(name: str) -> str:
    """How tables name scenario ``name`` (the name itself when it is not registered)."""
    cls = REGISTRY.get(name)
    return cls.label if cls is not None else name


def build(protocol: RunProtocol) -> Scenario:
    """The scenario of one run of ``protocol`` (fresh: a scenario keeps state)."""
    return scenario_class(protocol.task.scenario).create(protocol.task, protocol)


def other_tables(name: str) -> set[str]:
    """Protocol tables other scenarios read that scenario ``name`` does not."""
    cls = REGISTRY.get(name)
    own = set(cls.tables) if cls is not None else set()
    return {t for other in REGISTRY.values() for t in other.tables} - own


def _validate(value: Any, handler: core_schema.ValidatorFunctionWrapHandler) -> Any:
    """``[task]``: validated by the config model of the scenario it names."""
    if isinstance(value, dict):
        name = value.get("scenario", DEFAULT)
    elif isinstance(value, ScenarioConfig):
        name = value.scenario
    else:
        return handler(value)  # not a table: the type error
    cls = REGISTRY.get(name) if isinstance(name, str) else None
    if cls is None:
        error = PydanticCustomError(
            "unknown_scenario", "unknown scenario {name}; known: {known}",
            {"name": repr(name), "known": ", ".join(REGISTRY)})
        raise ValidationError.from_exception_data(
            "task", [{"type": error, "loc": ("scenario",), "input": name}])
    if isinstance(value, cls.config_model):
        return value
    data = value.model_dump() if isinstance(value, ScenarioConfig) else value
    return cls.config_model.model_validate({**data, "scenario": name})


class _RegistrySchema:
    """The JSON Schema of ``[task]``: one of the registered scenarios' config models."""

    def __get_pydantic_json_schema__(self, schema: core_schema.CoreSchema,
                                     handler: GetJsonSchemaHandler) -> JsonSchemaValue:
        models = [handler(cls.config_model.__pydantic_core_schema__)
                  for cls in REGISTRY.values()]
        return models[0] if len(models) == 1 else {"oneOf": models}


#: The ``[task]`` table: the config model of the scenario its ``scenario`` names.
TaskConfig = Annotated[SerializeAsAny[ScenarioConfig], WrapValidator(_validate),
                       _RegistrySchema()]


def is_default(config: ScenarioConfig) -> bool:
    """``[task]`` says nothing a protocol without it would not (the funnel alignment)."""
    return isinstance(config, FunnelTask)


__all__ = [
    "DEFAULT",
    "REGISTRY",
    "FunnelTask",
    "Scenario",
    "ScenarioConfig",
    "SourceChange",
    "TaskConfig",
    "Verdict",
    "build",
    "is_default",
    "label",
    "on_change",
    "other_tables",
    "register",
    "scenario_class",
    "scenario_topics",
]
