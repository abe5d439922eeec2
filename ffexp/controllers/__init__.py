"""The registry of ALIGN-phase methods: the paper's three and more.

A protocol picks one with ``[align] method = "..."``; the rest of the
``[align]`` table is that method's config model (a discriminated union built
from this registry, as ``[task]`` is from the scenarios', so pydantic names the
method's own fields in errors). To add a method: write one module with a
:class:`~ffexp.controllers.base.Controller` subclass whose ``config_model`` is
its table (``method: Literal["name"]``), and list the class in
:data:`_CONTROLLERS` below. Nothing else in ffexp names a method;
``schemas/protocol.json`` is generated from this registry.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated, Any, Protocol

from pydantic import Field

from ffexp.controllers.admittance import Admittance
from ffexp.controllers.base import Approach, ControlContext, Controller
from ffexp.controllers.force import Force, ForceRi
from ffexp.controllers.impedance import Impedance

_CONTROLLERS: tuple[type[Controller], ...] = (ForceRi, Force, Impedance, Admittance)

#: method name -> controller class
REGISTRY: dict[str, type[Controller]] = {cls.name: cls for cls in _CONTROLLERS}


class MethodConfig(Protocol):
    """What every method's ``[align]`` model has (its static type)."""

    @property
    def method(self) -> str: ...


def _align_union() -> Any:
    from typing import Union

    models = tuple(cls.config_model for cls in REGISTRY.values())
    # a Union built from the registry: pydantic reads it like a written-out ``A | B | C``
    return Annotated[Union[models], Field(discriminator="method")]  # noqa: UP007


if TYPE_CHECKING:
    AlignConfig = MethodConfig
else:
    #: The ``[align]`` table: one config model per method, told apart by ``method``.
    AlignConfig = _align_union()


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


def build_controller(config: MethodConfig, ctx: ControlContext) -> Controller:
    """The controller for an ``[align]`` config (its ``method`` picks the class)."""
    cls = controller_class(config.method)
    return cls(config, ctx)  # type: ignore[arg-type]


__all__ = [
    "REGISTRY",
    "AlignConfig",
    "Approach",
    "ControlContext",
    "Controller",
    "MethodConfig",
    "build_controller",
    "controller_class",
    "label",
    "tracks_force_reference",
]
