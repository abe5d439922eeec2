"""The UR back-end's errors that :mod:`drivers.errors` has no class for.

:class:`RtdeRefusedError`: the controller refused an RTDE request.
:class:`UrSafetyStopError`: the robot stopped for safety (protective stop,
safeguard stop, emergency stop, violation, fault); the loop ends the run on it.
"""

from __future__ import annotations

from drivers.errors import DriverError


class RtdeRefusedError(DriverError):
    """The controller refused a request: the protocol version, a recipe (variables
    NOT_FOUND or IN_USE), or start/pause.

    Args:
        address: the controller's ``host:port``.
        request: what was refused (``"protocol version 2"``, ``"an output recipe"``, ...).
        message: why, in one line.
        names: the refused variables (empty for other refusals).
    """

    def __init__(self, address: str, request: str, message: str,
                 names: tuple[str, ...] = ()) -> None:
        self.address = address
        self.request = request
        self.names = names
        super().__init__(f"{address}: RTDE controller refused {request}: {message}")


class UrSafetyStopError(DriverError):
    """The robot reported a safety stop in ``safety_status_bits``.

    Args:
        address: the controller's ``host:port``.
        stops: the set bits' names (``"protective_stopped"``, ...).
        safety_mode: the ``safety_mode`` name reported with them.
    """

    def __init__(self, address: str, stops: tuple[str, ...], safety_mode: str) -> None:
        self.address = address
        self.stops = stops
        self.safety_mode = safety_mode
        super().__init__(f"{address}: robot stopped for safety: {', '.join(stops)} "
                         f"(safety_mode {safety_mode})")
