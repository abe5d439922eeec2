"""The "not connected" guard every device back-end needs, written once."""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Concatenate, ParamSpec, Protocol, TypeVar

from drivers.errors import NotConnectedError

P = ParamSpec("P")
R = TypeVar("R")


class _Device(Protocol):
    @property
    def is_open(self) -> bool: ...


D = TypeVar("D", bound=_Device)


def requires_open(
    what: str,
) -> Callable[[Callable[Concatenate[D, P], R]], Callable[Concatenate[D, P], R]]:
    """Raise :class:`NotConnectedError` ("<what>: <method>() before connect/start") when
    the device's ``is_open`` is false. ``what`` names the device in the message."""

    def wrap(method: Callable[Concatenate[D, P], R]) -> Callable[Concatenate[D, P], R]:
        @functools.wraps(method)
        def guarded(self: D, /, *args: P.args, **kwargs: P.kwargs) -> R:
            if not self.is_open:
                raise NotConnectedError(f"{what}: {method.__name__}() before connect/start")
            return method(self, *args, **kwargs)

        return guarded

    return wrap
