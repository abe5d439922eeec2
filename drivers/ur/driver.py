"""``UrRobot``: a Universal Robots e-Series arm as a :class:`~drivers.base.interfaces.RobotDriver`.

The link is RTDE (:class:`~drivers.ur.rtde.client.RtdeClient`); the command
goes to ffexp's own URScript program (``drivers/ur/ffexp_control.script``,
register map in :mod:`drivers.ur.registers` and docs/ur.md), which the driver
sends over the controller's script port at connect (``script = "send"``) or
expects installed and running (``"installed"``).

- :meth:`UrRobot.measurements` is clocked by the controller's output stream
  (500 Hz on e-Series): one :class:`~drivers.base.types.RobotState` per data
  package, the newest when several arrived while the loop was busy (the
  skipped ones are counted in the extras). The pose is ``actual_TCP_pose``;
  the twist ``actual_TCP_speed`` and the robot's own wrench
  ``actual_TCP_force`` are rotated from the base frame into the TCF.
  ``link.commanding`` while the program runs and the robot is
  RUNNING; ``link.healthy`` while ``safety_mode`` is NORMAL or REDUCED.
- :meth:`UrRobot.send` writes the command into the input registers
  (:func:`~drivers.ur.registers.fill_command`); ``None`` holds the arm where
  it was last measured (status HELD). The applied command has the wrench
  zeroed on the axes that follow the pose (force mode acts on compliant axes
  only).
- A safety stop in ``safety_status_bits`` (protective, safeguard, emergency,
  violation, fault) raises :class:`~drivers.ur.errors.UrSafetyStopError`; a
  package that does not come within ``cycle_timeout_s`` raises
  :class:`~drivers.errors.DriverTimeoutError`; a closed or reset connection
  :class:`~drivers.errors.LinkLostError`. The loop ends the run on each
  (ABORT), naming the controller's address.
"""

from __future__ import annotations

import socket
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from importlib import resources
from typing import Final, Protocol

import numpy as np

from drivers.base.guards import requires_open
from drivers.base.interfaces import RobotDriver
from drivers.base.types import (
    AppliedCommand,
    ApplyStatus,
    CartesianCommand,
    Extras,
    LinkHealth,
    RobotState,
)
from drivers.errors import DriverError, DriverTimeoutError, LinkLostError
from drivers.net.udp import resolve_ipv4
from drivers.ur import registers
from drivers.ur.config import UrSettings
from drivers.ur.errors import UrSafetyStopError
from drivers.ur.rtde.client import RtdeClient
from drivers.ur.rtde.codec import ControllerVersion, DataPackage
from drivers.ur.rtde.fields import Recipe
from drivers.ur.rtde.variables import SAFETY_MODE, SAFETY_STATUS_BIT

#: The outputs the driver reads every cycle.
OUTPUT_NAMES: Final = ("timestamp", "actual_q", "actual_qd", "actual_TCP_pose",
                       "actual_TCP_speed", "actual_TCP_force", "ft_raw_wrench", "robot_mode",
                       "safety_mode", "safety_status_bits", "runtime_state",
                       registers.APPLIED_SEQ, registers.SCRIPT_STATE)
#: ``safety_status_bits`` that end a run.
STOP_BITS: Final = tuple((name, SAFETY_STATUS_BIT[name]) for name in (
    "protective_stopped", "safeguard_stopped", "system_emergency_stopped",
    "robot_emergency_stopped", "emergency_stopped", "violation", "fault"))
_STOP_MASK: Final = sum(1 << bit for _, bit in STOP_BITS)
ROBOT_MODE_RUNNING: Final = 7
SAFETY_OK: Final = (1, 2)  # NORMAL, REDUCED

SCRIPT_NAME: Final = "ffexp_control.script"
_WRENCH: Final = list(registers.WRENCH)  # (one multi-field index: every wrench register)


def control_script() -> str:
    """The text of ffexp's URScript program (package data of :mod:`drivers.ur`)."""
    try:
        return resources.files("drivers.ur").joinpath(SCRIPT_NAME).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise DriverError(f"drivers/ur/{SCRIPT_NAME} is missing from this installation "
                          "(package data); reinstall ffexp") from None


def send_script(host: str, port: int, text: str, timeout_s: float) -> None:
    """Send a URScript program to the controller's script port (it runs it at once)."""
    try:
        with socket.create_connection((host, port), timeout=timeout_s) as sock:
            sock.sendall(text.encode("utf-8"))
    except TimeoutError:
        raise DriverTimeoutError(f"{host}:{port}: the script port did not answer within "
                                 f"{timeout_s:g} s") from None
    except OSError as exc:
        raise LinkLostError(f"{host}:{port}: cannot send the URScript program: "
                            f"{exc.strerror or exc}") from None


@dataclass
class UrExtras(Extras):
    """What only a UR reports, per cycle (recorded on ``/robot/ur``: :mod:`drivers.ur.topics`)."""

    robot_mode: int = 0
    safety_mode: int = 0
    safety_status_bits: int = 0
    runtime_state: int = 0
    script_state: int = 0
    applied_seq: int = 0
    skipped_packages: int = 0
    """Data packages that arrived while the loop was busy and were skipped (so far)."""
    joint_vel_radps: np.ndarray = field(default_factory=lambda: np.zeros(6))
    ft_raw_wrench: np.ndarray = field(default_factory=lambda: np.zeros(6))
    """The flange sensor's raw wrench, as the controller reports it [N, N m]."""

    def topics(self) -> tuple[str, ...]:
        return ("/robot/ur",)


class RtdeLink(Protocol):
    """What :class:`UrRobot` uses of its link: :class:`~drivers.ur.rtde.client.RtdeClient`
    over TCP, or an in-process controller (:mod:`drivers.ur.emulate.lockstep`)."""

    @property
    def is_open(self) -> bool: ...
    skipped: int

    def connect(self) -> None: ...
    def close(self) -> None: ...
    def controller_version(self) -> ControllerVersion: ...
    def setup_outputs(self, names: Sequence[str], frequency_hz: float) -> Recipe: ...
    def setup_inputs(self, names: Sequence[str]) -> Recipe: ...
    def start(self) -> None: ...
    def receive_latest(self, timeout_s: float | None = None) -> DataPackage: ...
    def send(self, recipe: Recipe, values: Mapping[str, object] | np.ndarray) -> None: ...


def rtde_link(host: str, port: int, timeout_s: float) -> RtdeLink:
    """The RTDE client of a real (or emulated) controller at ``host:port``."""
    return RtdeClient(host, port, timeout_s=timeout_s)


class UrRobot(RobotDriver):
    """A UR arm over RTDE with ffexp's URScript program. ``where`` names the settings
    (a rig file and table) in address errors; ``link`` opens the link (RTDE over TCP
    unless given)."""

    def __init__(self, settings: UrSettings, where: str = "UrSettings",
                 link: Callable[[str, int, float], RtdeLink] = rtde_link) -> None:
        self.settings = settings
        self.where = where
        self.controller_version: ControllerVersion | None = None
        self._open_link = link
        self._client: RtdeLink | None = None
        self._listeners: list[Callable[[RobotState], None]] = []
        self._inputs: Recipe | None = None
        self._record: np.ndarray | None = None
        self._seq = 0
        self._cycle = 0
        self._time_ns: int | None = None
        self._pose = np.eye(4)
        s = settings
        self._speed_limits = np.array(s.compliant_speed_limits_mps_radps)
        self._deviation_limits = np.array(s.deviation_limits_m_rad)

    @property
    def connected(self) -> bool:
        return self._client is not None and self._client.is_open

    @property
    def address(self) -> str:
        return f"{self.settings.robot_ip}:{self.settings.rtde_port}"

    def connect(self) -> None:
        if self.connected:
            return
        s = self.settings
        host = resolve_ipv4(f"{self.where}.robot_ip", s.robot_ip)
        if s.script == "send":
            send_script(host, s.script_port, control_script(), s.connect_timeout_s)
        client = self._open_link(host, s.rtde_port, s.connect_timeout_s)
        client.connect()
        try:
            self.controller_version = client.controller_version()
            client.setup_outputs(OUTPUT_NAMES, s.frequency_hz)
            self._inputs = client.setup_inputs(registers.INPUT_NAMES)
            self._record = self._inputs.empty()
            client.start()
        except BaseException:
            client.close()
            raise
        self._client = client

    def close(self) -> None:
        """Tell the program to end (best effort), then close the link; idempotent."""
        client, self._client = self._client, None
        if client is None:
            return
        if client.is_open and self._inputs is not None and self._record is not None:
            # a clean hold command (the last one may have been refused, e.g. a NaN), ending
            self._fill(None)
            self._record[registers.MODE] = int(registers.Mode.END)
            try:
                client.send(self._inputs, self._record)
            except DriverError:  # best effort: the program holds a stale command anyway
                pass
        client.close()

    def _fill(self, command: CartesianCommand | None) -> None:
        assert self._record is not None
        s = self.settings
        self._seq += 1
        registers.fill_command(
            self._record, self._seq, command, self._pose,
            stiffness_max=s.force_axis_stiffness_npm_nmprad, speed_limits=self._speed_limits,
            deviation_limits=self._deviation_limits, damping=s.force_mode_damping,
            gain_scaling=s.force_mode_gain_scaling, lookahead_s=s.servo_lookahead_s,
            servo_gain=s.servo_gain)

    def now_ns(self) -> int | None:
        """The controller's time of the newest state [ns] (``None`` before the first):
        the clock an F/T sensor beside the UR stamps its samples in."""
        return self._time_ns

    def add_listener(self, callback: Callable[[RobotState], None]) -> None:
        """Call ``callback`` with every state, before :meth:`measurements` yields it
        (:class:`~drivers.ur.wrench.UrWrenchSensor` reads the robot's wrench this way)."""
        self._listeners.append(callback)

    @requires_open("UR robot")
    def measurements(self) -> Iterator[RobotState]:
        while self._client is not None:
            pkg = self._client.receive_latest(self.settings.cycle_timeout_s)
            state = self._state(pkg.record)
            for listener in self._listeners:
                listener(state)
            yield state

    def _state(self, rec: np.ndarray) -> RobotState:
        bits = int(rec["safety_status_bits"])
        if bits & _STOP_MASK:
            stops = tuple(name for name, bit in STOP_BITS if bits >> bit & 1)
            mode = int(rec["safety_mode"])
            raise UrSafetyStopError(self.address, stops, SAFETY_MODE.get(mode, str(mode)))
        pose = registers.pose_matrix(rec["actual_TCP_pose"])
        self._pose = pose
        rot_t = pose[:3, :3].T
        speed = np.asarray(rec["actual_TCP_speed"], dtype=np.float64)
        force = np.asarray(rec["actual_TCP_force"], dtype=np.float64)
        twist = np.concatenate((rot_t @ speed[:3], rot_t @ speed[3:]))
        wrench = np.concatenate((rot_t @ force[:3], rot_t @ force[3:]))
        script_state = int(rec[registers.SCRIPT_STATE])
        extras = UrExtras(int(rec["robot_mode"]), int(rec["safety_mode"]), bits,
                          int(rec["runtime_state"]), script_state, int(rec[registers.APPLIED_SEQ]),
                          self._client.skipped if self._client is not None else 0,
                          np.asarray(rec["actual_qd"], dtype=np.float64),
                          np.asarray(rec["ft_raw_wrench"], dtype=np.float64))
        link = LinkHealth(
            commanding=(script_state == registers.ScriptState.RUNNING
                        and extras.robot_mode == ROBOT_MODE_RUNNING),
            healthy=extras.safety_mode in SAFETY_OK, cycle=self._cycle,
            cycle_s=1.0 / self.settings.frequency_hz)
        self._cycle += 1
        self._time_ns = time_ns = round(float(rec["timestamp"]) * 1e9)
        return RobotState(time_ns=time_ns, tcp_pose_m=pose,
                          joint_pos_rad=np.asarray(rec["actual_q"], dtype=np.float64),
                          link=link, tcp_twist_mps_radps=twist, ext_wrench_n_nm=wrench,
                          extras=extras)

    @requires_open("UR robot")
    def send(self, command: CartesianCommand | None) -> AppliedCommand:
        assert self._client is not None and self._inputs is not None
        assert self._record is not None
        self._fill(command)
        self._client.send(self._inputs, self._record)
        if command is None:
            held = CartesianCommand(pose_m=self._pose.copy())
            return AppliedCommand(held, ApplyStatus.HELD)
        applied = command.copy()
        applied.wrench_n_nm[:] = self._record[_WRENCH].item()  # (the registers' doubles)
        return AppliedCommand(applied, ApplyStatus.APPLIED)
