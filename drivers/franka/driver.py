"""``FrankaRobot``: ffexp's Franka driver. It owns libfranka's 1 kHz torque loop and the
Cartesian impedance law with the wrench feed-forward (:mod:`drivers.franka.law`), as the
KRC and ffexp's URScript program do on theirs; ffexp's loop sets the law's set-point.

:meth:`FrankaRobot.measurements` runs the loop in the caller's thread: it yields the state
of one millisecond, and after the caller's :meth:`~FrankaRobot.send` runs the law for
that state and the ``setpoint_every - 1`` following ones, each with the set-point last
sent, before it yields again (so ffexp's loop runs at ``1 kHz / setpoint_every``). Before
the first command the law holds the pose the arm had at connect
(``hold_stiffness_npm_nmprad``, damping ratio 0.7); ``send(None)`` keeps the set-point.

Link health: ``commanding`` while the robot is in its move mode with the external
controller, ``healthy`` while libfranka's ``control_command_success_rate`` is at least
``min_success_rate``; states whose ids the driver skipped are counted (``missed_cycles``).
A reflex (robot mode REFLEX or error flags set) raises
:class:`~drivers.franka.errors.FrankaReflexError` naming the robot's flags; libfranka's
exceptions are mapped by :func:`~drivers.franka.errors.from_libfranka`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np

from drivers.base.guards import requires_open
from drivers.base.interfaces import RobotDriver
from drivers.base.types import (
    F64,
    AppliedCommand,
    ApplyStatus,
    CartesianCommand,
    Extras,
    LinkHealth,
    RobotState,
)
from drivers.errors import DriverError
from drivers.franka import codec
from drivers.franka.config import FrankaSettings
from drivers.franka.errors import FrankaReflexError, from_libfranka
from drivers.franka.law import ImpedanceLaw
from drivers.franka.link import FciLink, FciState, LibfrankaLink
from drivers.franka.model import ArmModel

__all__ = ["CYCLE_S", "FrankaExtras", "FrankaRobot"]

#: libfranka's torque cycle [s].
CYCLE_S = 0.001
_HOLD_DAMPING = 0.7


@dataclass
class FrankaExtras(Extras):
    """What a Franka reports besides the neutral state (``/robot/franka``)."""

    robot_mode: int = 0
    success_rate: float = 1.0
    missed_cycles: int = 0
    reflexes: int = 0
    tau_cmd_nm: F64 = field(default_factory=lambda: np.zeros(7))
    tau_ext_nm: F64 = field(default_factory=lambda: np.zeros(7))

    def topics(self) -> tuple[str, ...]:
        return ("/robot/franka",)


class FrankaRobot(RobotDriver):
    """A Franka over libfranka (module docstring). ``link`` opens the robot's loop
    (pylibfranka unless given: the in-process simulated FR3 passes its own)."""

    def __init__(self, settings: FrankaSettings, where: str = "FrankaSettings",
                 link: Callable[[], FciLink] | None = None) -> None:
        self.settings = settings
        self.where = where
        s = settings
        self._open_link = link or (lambda: LibfrankaLink(
            s.robot_ip, realtime=s.realtime, collision_torque_nm=s.collision_torque_nm,
            collision_force_n=s.collision_force_n, connect_timeout_s=s.connect_timeout_s))
        self.link: FciLink | None = None
        lin, rot = s.stiffness_max_npm_nmprad
        self.law = ImpedanceLaw(ArmModel(), stiffness_max=(lin, rot),
                                nullspace_damping=s.nullspace_damping_nmsprad,
                                nullspace_stiffness=s.nullspace_stiffness_nmprad)
        self._setpoint = CartesianCommand()
        self._state: FciState | None = None
        self._listeners: list[Callable[[RobotState], None]] = []
        self._cycle = 0
        self._first_id = 0
        self._missed = 0
        self._tau = np.zeros(7)

    @property
    def connected(self) -> bool:
        return self.link is not None

    @property
    def address(self) -> str:
        return f"{self.settings.robot_ip}:{codec.COMMAND_PORT}"

    def connect(self) -> None:
        if self.link is not None:
            return
        link = self._open_link()
        try:
            state = link.connect()
        except DriverError:
            link.close()
            raise
        except Exception as exc:  # libfranka's exceptions: the project's, in its words
            link.close()
            raise from_libfranka(self.address, exc) from None
        self.link, self._state = link, state
        self._first_id = state.message_id
        self.law.reset()
        lin, rot = self.settings.hold_stiffness_npm_nmprad
        self._setpoint = CartesianCommand(
            pose_m=state.o_t_ee.copy(), stiffness_npm_nmprad=np.array([lin] * 3 + [rot] * 3),
            damping_ratio=np.full(6, _HOLD_DAMPING), wrench_n_nm=np.zeros(6))

    def close(self) -> None:
        link, self.link = self.link, None
        if link is not None:
            link.close()

    def now_ns(self) -> int | None:
        """The robot's time of the newest state [ns] (``None`` before the first)."""
        return None if self._state is None else round(self._state.message_id * 1e6)

    def add_listener(self, callback: Callable[[RobotState], None]) -> None:
        """Call ``callback`` with every state before :meth:`measurements` yields it."""
        self._listeners.append(callback)

    def _read(self) -> FciState:
        assert self.link is not None
        try:
            state = self.link.read_once()
        except DriverError:
            raise
        except Exception as exc:
            raise from_libfranka(self.address, exc) from None
        if self._state is not None and state.message_id > self._state.message_id + 1:
            self._missed += state.message_id - self._state.message_id - 1
        self._state = state
        if state.robot_mode == codec.RobotMode.REFLEX or state.errors:
            raise FrankaReflexError(self.address, state.errors or state.reflex)
        return state

    def _cycle_law(self, state: FciState) -> None:
        assert self.link is not None
        tau = self.law.torque(state.q, state.dq, state.o_t_ee, state.f_t_ee, self._setpoint)
        self._tau = tau
        try:
            self.link.write_once(tau)
        except DriverError:
            raise
        except Exception as exc:
            raise from_libfranka(self.address, exc) from None

    @requires_open("Franka robot")
    def measurements(self) -> Iterator[RobotState]:
        every = self.settings.setpoint_every
        state = self._state
        assert state is not None
        while self.link is not None:
            robot_state = self._robot_state(state)
            for listener in self._listeners:
                listener(robot_state)
            yield robot_state
            if self.link is None:
                return
            self._cycle_law(state)
            for _ in range(every - 1):
                state = self._read()
                self._cycle_law(state)
            state = self._read()

    def _robot_state(self, state: FciState) -> RobotState:
        pose = state.o_t_ee
        rot_t = pose[:3, :3].T
        wrench = np.concatenate((rot_t @ state.o_f_ext[:3], rot_t @ state.o_f_ext[3:]))
        jac, _ = self.law.model.jacobian_tcf(state.q, state.f_t_ee)
        extras = FrankaExtras(state.robot_mode, state.success_rate, self._missed,
                              len(state.errors), self._tau.copy(), state.tau_ext.copy())
        link = LinkHealth(commanding=state.robot_mode == codec.RobotMode.MOVE,
                          healthy=state.success_rate >= self.settings.min_success_rate,
                          cycle=self._cycle, cycle_s=CYCLE_S * self.settings.setpoint_every)
        self._cycle += 1
        return RobotState(time_ns=round((state.message_id - self._first_id) * CYCLE_S * 1e9),
                          tcp_pose_m=pose.copy(), joint_pos_rad=state.q.copy(), link=link,
                          tcp_twist_mps_radps=jac @ state.dq, ext_wrench_n_nm=wrench,
                          extras=extras)

    @requires_open("Franka robot")
    def send(self, command: CartesianCommand | None) -> AppliedCommand:
        if command is None:
            return AppliedCommand(self._setpoint.copy(), ApplyStatus.HELD)
        self._setpoint = command.copy()
        k = np.asarray(command.stiffness_npm_nmprad, dtype=np.float64)
        lin, rot = self.settings.stiffness_max_npm_nmprad
        hi = np.array([lin] * 3 + [rot] * 3)
        applied = command.copy()
        applied.stiffness_npm_nmprad = np.clip(k, 0.0, hi)
        status = ApplyStatus.CLIPPED if np.any(applied.stiffness_npm_nmprad != k) \
            else ApplyStatus.APPLIED
        return AppliedCommand(applied, status)
