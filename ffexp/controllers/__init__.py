"""The registry of ALIGN-phase methods: the paper's three and more.

A protocol picks one with ``[align] method = "..."``; the rest of the
``[align]`` table is that method's config model (a discriminated union, so
pydantic names the method's own fields in errors). To add a method: write
one module with a :class:`~ffexp.controllers.base.Controller` subclass and
its config model (``method: Literal["name"]``), and list both in
:data:`_METHODS` below. Nothing else in ffexp names a method.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Field

from ffexp.controllers.admittance import Admittance, AdmittanceConfig
from ffexp.controllers.base import Approach, ControlContext, Controller
from ffexp.controllers.force import Force, ForceConfig, ForceRi, ForceRiConfig
from ffexp.controllers.impedance import Impedance, ImpedanceAlignConfig

_METHODS: tuple[tuple[type[Controller], type], ...] = (
    (ForceRi, ForceRiConfig),
    (Force, ForceConfig),
    (Impedance, ImpedanceAlignConfig),
    (Admittance, AdmittanceConfig),
)

#: method name -> controller class
REGISTRY: dict[str, type[Controller]] = {cls.name: cls for cls, _ in _METHODS}

#: The ``[align]`` table: one config model per method, told apart by ``method``.
AlignConfig = Annotated[
    ForceRiConfig | ForceConfig | ImpedanceAlignConfig | AdmittanceConfig,
    Field(discriminator="method"),
]


def controller_class(method: str) -> type[Controller]:
    """The controller registered as ``method`` (KeyError names the known ones)."""
    try:
        return REGISTRY[method]
    except KeyError:
        raise KeyError(f"unknown method {method!r}; known: {', '.join(REGISTRY)}") from None


def label(method: str) -> str:
    """How tables name ``method`` (the name itself when it is not registered)."""
    cls = REGISTRY.get(method)
    return cls.label if cls is not None else method


def tracks_force_reference(method: str) -> bool:
    """Whether f_z tracking is a metric of ``method`` (False when unknown)."""
    cls = REGISTRY.get(method)
    return cls is not None and cls.tracks_force_reference


def build(config: object, ctx: ControlContext) -> Controller:
    """The controller for an ``[align]`` config (its ``method`` picks the class)."""
    cls = controller_class(str(getattr(config, "method", "")))
    return cls(config, ctx)  # type: ignore[arg-type]


__all__ = [
    "REGISTRY",
    "AlignConfig",
    "Approach",
    "ControlContext",
    "Controller",
    "build",
    "controller_class",
    "label",
    "tracks_force_reference",
]
