"""The one RTDE error :mod:`drivers.errors` has no class for: a request the controller refused."""

from __future__ import annotations

from drivers.errors import DriverError


class RtdeRefusedError(DriverError):
    """The controller refused a request: the protocol version, a recipe (variables
    NOT_FOUND or IN_USE), or start/pause.

    Args:
        address: the controller's ``host:port``.
        request: what was refused (``"protocol version 2"``, ``"output recipe"``, ...).
        message: why, in one line.
        names: the refused variables (empty for other refusals).
    """

    def __init__(self, address: str, request: str, message: str,
                 names: tuple[str, ...] = ()) -> None:
        self.address = address
        self.request = request
        self.names = names
        super().__init__(f"{address}: RTDE controller refused {request}: {message}")
