"""The driver's link to the robot's 1 kHz loop: read a state, write the torques for it.

:class:`FciState` is one state as the driver uses it, read from libfranka's
``RobotState`` (:class:`LibfrankaLink`, over pylibfranka: the optional extra ``franka``,
imported when the link opens) or from the wire record itself
(:func:`state_from_record`: the in-process simulated FR3 goes through the codec, so its
values are the float32 ones libfranka would have handed over).

Before libfranka connects, :func:`probe` asks the robot's command port for its protocol
version itself, with a timeout: libfranka waits for the answer to its ``Connect``
without one (a robot that never answers would hang the run), and its refusal of another
version is best said with both versions and the address.
"""

from __future__ import annotations

import select
import socket
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, Protocol

import numpy as np

from drivers.base.types import F64
from drivers.errors import DriverTimeoutError, LinkLostError
from drivers.franka import codec
from drivers.franka.errors import FrankaVersionError

__all__ = ["FciLink", "FciState", "LibfrankaLink", "probe", "state_from_record"]

#: The protocol version of the libfranka the ``franka`` extra pins (0.21.3).
LIBRARY_VERSION = codec.VERSION


def probe(host: str, timeout_s: float, port: int = codec.COMMAND_PORT,
          version: int = LIBRARY_VERSION) -> int:
    """Connect to the robot's command port, send ``Connect`` with ``version`` and return the
    server's version; one line naming the address otherwise: no connection
    (:class:`~drivers.errors.LinkLostError`), no answer within ``timeout_s``
    (:class:`~drivers.errors.DriverTimeoutError`), another version
    (:class:`~drivers.franka.errors.FrankaVersionError`, both versions named)."""
    address = f"{host}:{port}"
    try:
        sock = socket.create_connection((host, port), timeout=timeout_s)
    except TimeoutError:
        raise DriverTimeoutError(f"franka {address}: no connection within "
                                 f"{timeout_s:g} s") from None
    except OSError as exc:
        raise LinkLostError(f"franka {address}: {exc.strerror or exc}") from None
    with sock, socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as udp:
        udp.bind(("0.0.0.0", 0))  # where the robot may stream; nothing is read here
        sock.sendall(codec.message(codec.CONNECT_REQUEST, codec.Command.CONNECT, 0,
                                   version=version, udp_port=udp.getsockname()[1]))
        data = b""
        size = codec.CONNECT_RESPONSE.itemsize
        while len(data) < size:
            ready, _, _ = select.select([sock], [], [], timeout_s)
            chunk = sock.recv(size - len(data)) if ready else None
            if chunk is None:
                raise DriverTimeoutError(f"franka {address}: no answer to Connect within "
                                         f"{timeout_s:g} s")
            if not chunk:
                raise LinkLostError(f"franka {address}: the robot closed the connection "
                                    "before answering Connect")
            data += chunk
    rec = codec.decode(codec.CONNECT_RESPONSE, data)
    server = int(rec["version"])
    if int(rec["status"]) == codec.ConnectStatus.INCOMPATIBLE_LIBRARY_VERSION:
        raise FrankaVersionError(f"franka {address}: incompatible version: the robot speaks "
                                 f"{server}, libfranka here {version}")
    return server


@dataclass
class FciState:
    """One millisecond's robot state (the fields the driver reads)."""

    message_id: int
    q: F64
    dq: F64
    o_t_ee: F64
    """The EE's pose in the base frame (4x4)."""
    f_t_ee: F64
    """The EE (ffexp's TCP) in the flange frame (4x4)."""
    o_f_ext: F64
    """The external wrench estimate at the EE, base frame [N, N m]."""
    tau_ext: F64
    robot_mode: int
    success_rate: float
    errors: list[str] = field(default_factory=list)
    reflex: list[str] = field(default_factory=list)


def _matrix(values: Sequence[float] | np.ndarray) -> F64:
    return np.asarray(values, dtype=np.float64).reshape(4, 4, order="F")


def state_from_record(rec: np.void) -> FciState:
    """An :class:`FciState` from a :data:`~drivers.franka.codec.ROBOT_STATE` record (float32
    values widened to double, as libfranka does). The flags' names are read only when a
    flag is set; the tool ``F_T_EE`` (the same every millisecond) is made once while its
    bytes are the same (a read-only array)."""
    f64 = np.float64
    errors, reflex = rec["errors"], rec["reflex_reason"]
    tool = rec["F_T_EE"]
    return FciState(
        message_id=int(rec["message_id"]),
        q=np.asarray(rec["q"], dtype=f64), dq=np.asarray(rec["dq"], dtype=f64),
        o_t_ee=_matrix(rec["O_T_EE"]), f_t_ee=_tool_matrix(tool.tobytes(), tool.dtype.str),
        o_f_ext=np.asarray(rec["O_F_ext_hat_K"], dtype=f64),
        tau_ext=np.asarray(rec["tau_ext_hat_filtered"], dtype=f64),
        robot_mode=int(rec["robot_mode"]),
        success_rate=float(rec["control_command_success_rate"]),
        errors=codec.error_names(errors) if errors.any() else [],
        reflex=codec.error_names(reflex) if reflex.any() else [])


@lru_cache(maxsize=4)
def _tool_matrix(values: bytes, dtype: str) -> F64:
    """The tool ``F_T_EE`` of a record (its values' bytes and dtype) as a read-only matrix,
    made once while it stays the same (it is, every millisecond)."""
    f_t_ee = _matrix(np.frombuffer(values, dtype=dtype))
    f_t_ee.flags.writeable = False
    return f_t_ee


class FciLink(Protocol):
    """The robot's side of the torque loop, as the driver needs it."""

    @property
    def address(self) -> str: ...

    def connect(self) -> FciState:
        """Open the link, start the torque loop; the first state."""
        ...

    def read_once(self) -> FciState:
        """The next state (blocks until it comes)."""
        ...

    def write_once(self, tau: F64) -> None:
        """The torques for the state last read."""
        ...

    def close(self) -> None: ...


def _errors(errors: Any) -> list[str]:
    return [n for n in codec.ERROR_NAMES if bool(getattr(errors, n, False))]


class LibfrankaLink:
    """The torque loop of a real robot (or any FCI server) through pylibfranka."""

    def __init__(self, host: str, *, realtime: str, collision_torque_nm: float,
                 collision_force_n: float, connect_timeout_s: float = 5.0) -> None:
        self.host = host
        self.connect_timeout_s = connect_timeout_s
        self.realtime = realtime
        self.collision = (collision_torque_nm, collision_force_n)
        self._robot: Any = None
        self._control: Any = None
        self._plf: Any = None

    @property
    def address(self) -> str:
        return f"{self.host}:{codec.COMMAND_PORT}"

    def connect(self) -> FciState:
        import pylibfranka as plf  # type: ignore[import-not-found, unused-ignore]

        probe(self.host, self.connect_timeout_s)

        self._plf = plf
        mode = plf.RealtimeConfig.kEnforce if self.realtime == "enforce" \
            else plf.RealtimeConfig.kIgnore
        self._robot = robot = plf.Robot(self.host, mode)
        tau, force = self.collision
        robot.set_collision_behavior([tau] * 7, [tau] * 7, [force] * 6, [force] * 6)
        self._control = robot.start_torque_control()
        return self.read_once()

    def read_once(self) -> FciState:
        s, _period = self._control.readOnce()
        return FciState(
            message_id=round(s.time.to_sec() * 1000), q=np.asarray(s.q, dtype=np.float64),
            dq=np.asarray(s.dq, dtype=np.float64), o_t_ee=_matrix(s.O_T_EE),
            f_t_ee=_matrix(s.F_T_EE), o_f_ext=np.asarray(s.O_F_ext_hat_K, dtype=np.float64),
            tau_ext=np.asarray(s.tau_ext_hat_filtered, dtype=np.float64),
            robot_mode=int(s.robot_mode.value) if hasattr(s.robot_mode, "value")
            else int(s.robot_mode),
            success_rate=float(s.control_command_success_rate),
            errors=_errors(s.current_errors), reflex=_errors(s.last_motion_errors))

    def write_once(self, tau: F64) -> None:
        self._control.writeOnce(self._plf.Torques([float(t) for t in tau]))

    def close(self) -> None:
        robot, self._robot, self._control = self._robot, None, None
        if robot is not None:
            try:
                robot.stop()
            except Exception:
                pass
