"""The simulated LWR4+ in-process: the KRC of :mod:`drivers.fri.emulate.krc` in lockstep,
no sockets.

``SimRobot.measurements()`` yields the state of the current cycle; when the
caller asks for the next one, the world runs one cycle with the arm command
the KRC took ``fri.command_delay_cycles`` cycles ago
(:class:`~drivers.fri.emulate.krc.CommandDelay`; 0: from the last
:meth:`SimRobot.send`; none: the world holds the last one). The link is the
same state machine as the UDP emulator's
(:class:`~drivers.fri.link.KrcLink`, every cycle answered unless the caller
skips a ``send``): MON until ``start_cycles`` answered cycles with PERFECT
quality (the 100th answer at the earliest), then CMD; the command of that
cycle is the first one applied. ``start_cycles = 0`` starts in CMD.

Software limit switches (:func:`~drivers.fri.emulate.krc.software_limit_error`):
when a joint reaches its limit at the end of a cycle, the KRC leaves CMD and
latches the error (that cycle's measurement reports MON and the ``error``
bits), the next cycle brakes the arm where it is
(:func:`~drivers.fri.emulate.krc.brake_command`), and the driver then raises
:class:`~drivers.errors.DriverError` naming the joint, so the runner aborts
with that reason; no reported joint is ever beyond its software limit by more
than one cycle's motion, nor beyond its hardware range.

Commands go through :func:`~drivers.fri.command.to_fri_command` like on the
wire (a mirror while MON, HELD for ``None``), so the recordings
(``/robot/measurement``, ``/robot/link``, ``/robot/command``) are those of an
FRI robot. With ``wire_precision`` the measurement and the command also go
through the FRI codec (float32 on the wire, as over UDP), so a run equals the
same run against the UDP emulator in lockstep (``tests/test_emulate_fri.py``).
Listeners (:meth:`SimRobot.add_listener`, e.g. the KRC's wrench estimate read as
an F/T sensor) see every measurement, as with the UDP driver.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import Final

import numpy as np

from drivers.base.backend import OpenContext, OpenedRobot
from drivers.base.guards import requires_open
from drivers.base.impedance import clip_cart_stiffness
from drivers.base.interfaces import RobotDriver
from drivers.base.types import (
    AppliedCommand,
    ApplyStatus,
    CartesianCommand,
    LinkHealth,
    RobotState,
)
from drivers.description.scene import Scene, load_scene
from drivers.errors import DriverError, NotConnectedError
from drivers.fri.codec import (
    CmdArrays,
    MsrArrays,
    decode_cmd_into,
    decode_msr_into,
    encode_cmd,
    encode_msr,
    new_cmd_buffer,
    new_msr_buffer,
)
from drivers.fri.command import CARTESIAN_FLAGS, robot_state_from_fri, to_fri_command
from drivers.fri.config import SimRobotConfig
from drivers.fri.convert import (
    arrays_to_command,
    arrays_to_measurement,
    command_to_arrays,
    measurement_to_arrays,
)
from drivers.fri.emulate.krc import (
    SOFTWARE_LIMITS_DEG,
    CommandDelay,
    StateMeasurement,
    arm_command_from_fri,
    brake_command,
    control_mode,
    measurement_head,
    measurement_of,
    software_limit_error,
    software_limits_rad,
    state_free_head,
    stop_command,
)
from drivers.fri.link import KrcLink, LinkEvent
from drivers.fri.stats import LinkWatch
from drivers.fri.types import (
    CmdFlags,
    ControlMode,
    FriCommand,
    FriMeasurement,
    FriQuality,
    FriState,
)
from drivers.world.arm import ArmCommand, ArmMode, ArmState
from drivers.world.ftstream import SimFtSensor
from drivers.world.world import SimWorld

__all__ = ["SimRobot", "open_rig_robot", "open_sim"]

_WHAT = "sim robot"
_CARTSTIFF = int(CmdFlags.CARTSTIFF)  # ``int & IntFlag`` goes through the enum machinery
_TCPFT = int(CmdFlags.TCPFT)
_CMD = FriState.CMD
_FALLBACK = LinkEvent.FALLBACK
_CARTESIAN = int(CARTESIAN_FLAGS)
_CART_IMPEDANCE = ControlMode.CART_IMPEDANCE
_APPLIED = ApplyStatus.APPLIED
_UNACCEPTABLE = FriQuality.UNACCEPTABLE
_new: Final = object.__new__

# The lockstep FRI command's arrays are views of one buffer (its fields in this order),
# so that a delayed command is one copy (:meth:`SimRobot.send`) and its gains one
# slice (the stiffness and the damping side by side: :data:`_GAINS`).
_CMD_FIELDS: Final = (("cart_pos", (4, 4)), ("cart_stiffness", (6,)), ("cart_damping", (6,)),
                      ("add_tcp_ft", (6,)), ("jnt_pos", (7,)), ("add_jnt_trq", (7,)),
                      ("jnt_stiffness", (7,)), ("jnt_damping", (7,)))
_GAINS: Final = slice(16, 28)
#: The wrench of an applied command without TCPFT (read-only: shared).
_NO_WRENCH: Final = np.zeros(6)
_NO_WRENCH.flags.writeable = False


def _views(obj: object, layout: tuple[tuple[str, tuple[int, ...]], ...]) -> np.ndarray:
    """Make ``obj``'s arrays named in ``layout`` views of one new buffer, their values
    kept; returns the buffer."""
    buf = np.zeros(sum(int(np.prod(shape)) for _, shape in layout))
    i = 0
    for name, shape in layout:
        n = int(np.prod(shape))
        view = buf[i:i + n].reshape(shape)
        view[...] = getattr(obj, name)
        setattr(obj, name, view)
        i += n
    return buf


def _buffered_command() -> tuple[np.ndarray, FriCommand]:
    """A new ``FriCommand()`` whose arrays are views of one buffer (:data:`_CMD_FIELDS`)."""
    fri = FriCommand()
    return _views(fri, _CMD_FIELDS), fri


class SimRobot(RobotDriver):
    """LWR4+ over FRI, simulated in lockstep (module docstring).

    Args:
        world: the world to step.
        max_cycles: stop yielding after this many cycles (``None``: forever).
        start_cycles: answered cycles before CMD (100, as a friStart script).
        max_consecutive_misses: cycles without ``send`` in a row that end CMD.
        software_limits_deg: the KRC's software limit switches A1..A7 [deg]
            (default :data:`~drivers.fri.emulate.krc.SOFTWARE_LIMITS_DEG`).
        wire_precision: round the measurement and the command through the FRI
            codec, as the UDP link does.
    """

    def __init__(
        self,
        world: SimWorld,
        max_cycles: int | None = None,
        start_cycles: int = 100,
        max_consecutive_misses: int = 5,
        software_limits_deg: Sequence[float] = SOFTWARE_LIMITS_DEG,
        wire_precision: bool = False,
    ) -> None:
        self.world = world
        self.wire_precision = wire_precision
        self._listeners: list[Callable[[FriMeasurement], None]] = []
        self._wire = (MsrArrays(), MsrArrays(), new_msr_buffer(),
                      CmdArrays(), CmdArrays(), new_cmd_buffer())
        self.software_limits_rad = software_limits_rad(software_limits_deg)
        # no joint is within the smallest limit: none can be at its own (a cheap test)
        self._limit_min_rad = min(self.software_limits_rad.tolist())
        # arm commands of the lockstep FRI command or a slot's (their arrays shared), per
        # (slot or -1, flags, control, arm mode): the same object while they do not change
        self._arm_commands: dict[tuple[int, CmdFlags, ControlMode, ArmMode], ArmCommand] = {}
        # the last one of the lockstep command acting at once, and its key
        self._now_arm: ArmCommand | None = None
        self._now_flags: CmdFlags | None = None
        self._now_control: ControlMode | None = None
        self._now_mode: ArmMode | None = None
        self._brake = False
        self._stopped: str | None = None
        self.max_cycles = max_cycles
        self.start_cycles = start_cycles
        self.max_consecutive_misses = max_consecutive_misses
        self.link = self._new_link()
        self.delay = CommandDelay(world.scene.fri.command_delay_cycles)
        self._watch = LinkWatch()
        self._open = False
        self._answered = False
        self._fri_buf, self._fri = _buffered_command()
        fri = self._fri
        self._gain_values = self._fri_buf[_GAINS]
        # what send() returns: its command the FRI command's own arrays (module _NO_WRENCH)
        self._as_sent = CartesianCommand(fri.cart_pos, fri.cart_stiffness, fri.cart_damping,
                                         fri.add_tcp_ft)
        self._as_sent_no_wrench = CartesianCommand(fri.cart_pos, fri.cart_stiffness,
                                                   fri.cart_damping, _NO_WRENCH)
        self._applied = AppliedCommand(self._as_sent_no_wrench, ApplyStatus.APPLIED, fri)
        # a delayed command waits in a slot of its own (delay + 1 of them, in turn)
        self._slots = [_buffered_command() for _ in range(self.delay.cycles + 1)
                       ] if self.delay.cycles else []
        self._slot = 0
        # per slot, its last arm command and the key it was made for (flags, control, mode)
        self._slot_arms: list[tuple[CmdFlags, ControlMode, ArmMode, ArmCommand] | None] = [
            None] * len(self._slots)
        self._pending: ArmCommand | None = None  # the slot's arm command of the last send
        # the measurement's fields that are not the world's, while the link keeps them
        self._head: dict[str, object] = {}
        self._bare_head: dict[str, object] = {}  # the head without a state's fields
        self._msr: FriMeasurement
        self._head_changes = -1  # link.changes when the head was built (-1: build it)
        self._state: ArmState = world.last_state
        self._gains: tuple[bytes, tuple[CartesianCommand, CartesianCommand] | None] | None = None
        self._next: RobotState | None = None
        # the robot state's link health of the head: (commanding, healthy)
        self._health = (False, False)
        self._measure(world.last_state)

    def _new_link(self) -> KrcLink:
        self._cycle_s = self.world.cycle_s  # the link's cycle, reported in every measurement
        self._head_changes = -1  # a new link: a new head, and the watch sees it
        return KrcLink(
            self._cycle_s,
            start_cycles=self.start_cycles,
            max_consecutive_misses=self.max_consecutive_misses,
            timing=False,
        )

    def _measure(self, state: ArmState) -> None:
        """The measurement of ``state``, the world's last state (held: its truth is read
        next), and the robot state of it that :meth:`measurements` yields next.

        Without ``wire_precision`` the measurement is a
        :class:`~drivers.fri.emulate.krc.StateMeasurement` (the state's fields read
        when first read: the same values as
        :func:`~drivers.fri.emulate.krc.measurement_of`), and the link's fields of both
        are built again only when the link changed."""
        link = self.link
        self._state = state
        changed = link.changes != self._head_changes
        if changed:  # (the head's key: the link's count of changes, the link, the cycle)
            self._head = measurement_head(self._cycle_s, link.state, link.quality,
                                          link.error, link.rates(), link.missed)
            self._bare_head = state_free_head(self._head)
            self._head_changes = link.changes
            self._health = (link.state == _CMD, link.quality > _UNACCEPTABLE)
        if self.wire_precision:
            self._measure_wire(state, changed)
            return
        m: StateMeasurement = _new(StateMeasurement)
        d = self._bare_head.copy()
        d["link_events"] = []
        m.__dict__ = d
        m.arm_state = state
        # robot_state_from_fri(m) with the state's values and truth, inline (the same
        # fields in the same order; tests/test_lockstep_fast.py); its link health's
        # values kept while the link does not change
        health = _new(LinkHealth)
        health.commanding, health.healthy = self._health
        health.cycle = state.cycle
        health.cycle_s = self._cycle_s  # (both sample times of the head)
        rs: RobotState = _new(RobotState)
        rs.time_ns = state.time_ns
        rs.tcp_pose_m = state.tcp_pose_m
        rs.joint_pos_rad = state.jnt_pos_rad
        rs.link = health
        rs.tcp_twist_mps_radps = None
        rs.ext_wrench_n_nm = state.ext_wrench_n_nm
        rs.truth = state.truth
        rs.extras = m
        if changed:  # (else the state and quality are those the watch saw last)
            self._watch.see(m, m.link_events)  # state and quality changes, as the UDP driver
        if self._listeners:
            for listener in self._listeners:
                listener(m)
        self._msr = m
        self._next = rs

    def _measure_wire(self, state: ArmState, changed: bool) -> None:
        """:meth:`_measure` with ``wire_precision``: a new measurement as the UDP driver
        decodes it, and a new robot state of it."""
        m = self._over_the_wire(measurement_of(self._head, state))
        if changed:
            self._watch.see(m, m.link_events)
        for listener in self._listeners:
            listener(m)
        self._msr = m
        rs = robot_state_from_fri(m)
        rs.truth = state.truth
        self._next = rs

    def _over_the_wire(self, m: FriMeasurement) -> FriMeasurement:
        """``m`` as the UDP driver would decode it (a new measurement, own arrays)."""
        out, back, buf = self._wire[:3]
        measurement_to_arrays(m, out)
        out.send_seq = m.seq & 0xFFFF
        decode_msr_into(encode_msr(out, buf), back)
        return arrays_to_measurement(back, m.seq, m.time_ns)

    def _taken(self) -> FriCommand:
        """The command the KRC takes: the answer, through the codec with ``wire_precision``."""
        if not self.wire_precision:
            return self._fri
        out, back, buf = self._wire[3:]
        command_to_arrays(self._fri, out)
        decode_cmd_into(encode_cmd(out, buf), back)
        return arrays_to_command(back, control_mode(self.world.mode))

    def add_listener(self, callback: Callable[[FriMeasurement], None]) -> None:
        """Call ``callback(m)`` with every new measurement (as :class:`FriRobot` does)."""
        self._listeners.append(callback)

    def _robot_state(self) -> RobotState:
        """The robot state of the current measurement: a new object each call (the one
        :meth:`_measure` built, the first time)."""
        rs = self._next
        if rs is None:
            rs = robot_state_from_fri(self._msr)
            rs.truth = self._state.truth
        else:
            self._next = None
        return rs

    # ------------------------------------------------------------ lifecycle
    def connect(self) -> None:
        """Open the link: a fresh KRC link state (MON unless ``start_cycles`` is 0)."""
        self.link = self._new_link()
        self.delay.clear()
        self._watch = LinkWatch()
        self._answered = False
        self._brake = False
        self._stopped = None
        self._measure(self.world.last_state)
        self._open = True

    def close(self) -> None:
        self._open = False

    @property
    def connected(self) -> bool:
        return self._open

    @property
    def measurement(self) -> FriMeasurement:
        """The FRI measurement of the current cycle."""
        return self._msr

    # ------------------------------------------------------------ cycles
    @requires_open(_WHAT)
    def measurements(self) -> Iterator[RobotState]:
        return self._measurements()

    def _measurements(self) -> Iterator[RobotState]:
        n = 0
        while self._open:
            rs = self._next  # _robot_state(), inline
            if rs is None:
                rs = self._robot_state()
            else:
                self._next = None
            yield rs
            n += 1
            if self.max_cycles is not None and n >= self.max_cycles:
                return
            if not self._open:
                return
            self._advance()
            if self._stopped is not None and not self._brake:
                raise DriverError(self._stopped)

    def _advance(self) -> None:
        """One KRC cycle: account the answer, step the world with what the KRC takes."""
        world = self.world
        link = self.link
        event = link.cycle(self._answered, 0.0)
        arm: ArmCommand | None = None
        if self._brake:  # the KRC stopped the robot at the end of the last cycle
            arm = brake_command(world.last_state)
            self._brake = False
            self.delay.clear()
        elif event is _FALLBACK:
            arm = stop_command(world.last_state)
            self.delay.clear()
        elif not (self._answered and link.state == _CMD):  # no answer, or not taken
            arm = self.delay.push(None)[0]
        elif self._slots and not self.wire_precision:  # it acts later (_delayed, inline)
            # send() put the answer in the slot after the last one taken, and its arm command
            self._slot = (self._slot + 1) % len(self._slots)
            queue = self.delay.queue  # delay.push(arm, copy=False)[0], inline
            queue.append((self._pending, None))
            arm = queue.popleft()[0]
        elif self.wire_precision:  # the KRC takes the answer, as the wire carried it
            arm = self._delayed(self._taken())
        else:  # it takes the answer, acting at once: _arm_command(fri, -1), kept
            fri = self._fri
            mode = world.mode
            if (fri.flags is self._now_flags and fri.control is self._now_control
                    and mode is self._now_mode and self._now_arm is not None):
                arm = self._now_arm
            else:
                arm = self._now_arm = self._arm_command(fri, -1)
                self._now_flags, self._now_control, self._now_mode = fri.flags, fri.control, mode
        self._answered = False
        world.advance(arm)
        state = world.last_state
        # the measurement reads the joints and dynamics, the runner's state the truth:
        # every field, built at once (not group by group on a missing attribute)
        state.resolve()
        if not link.error:
            q = state.jnt_pos_rad
            ql = q.tolist()
            lo = self._limit_min_rad
            if max(ql) >= lo or min(ql) <= -lo:
                error = software_limit_error(q, self.software_limits_rad)
                if error:
                    link.fault(error)
                    self._brake = True
                    self._stopped = _stop_message(error, q, self.software_limits_rad)
        self._measure(state)

    def _delayed(self, fri: FriCommand) -> ArmCommand | None:
        """The arm command that acts this cycle when the KRC takes ``fri``: this one's,
        or with a delay the one taken ``command_delay_cycles`` ago
        (:class:`~drivers.fri.emulate.krc.CommandDelay`). With a delay, the lockstep
        command waits in the next of ``delay + 1`` slots (a copy of its buffer, which no
        command in flight holds): :meth:`_advance` does that inline."""
        if self.wire_precision:  # a new FriCommand each cycle: its arrays are its own
            return self.delay.push(arm_command_from_fri(fri, self.world.mode), copy=False)[0]
        return self._arm_command(fri, -1)

    def _arm_command(self, fri: FriCommand, slot: int) -> ArmCommand:
        """:func:`~drivers.fri.emulate.krc.arm_command_from_fri` of ``fri``, the lockstep
        command (``slot`` -1) or a slot's: the same object (its arrays shared) while the
        flags, control and arm mode do not change."""
        key = (slot, fri.flags, fri.control, self.world.mode)
        arm = self._arm_commands.get(key)
        if arm is None:
            arm = self._arm_commands[key] = arm_command_from_fri(fri, self.world.mode)
        return arm

    def send(self, command: CartesianCommand | None) -> AppliedCommand:
        """Answer this cycle (``None``: hold); returns what the KRC takes.

        The returned object is reused by the next ``send()`` (copy it to keep
        it); ``command`` is copied. CLIPPED: the world will clip the stiffness
        (beyond the arm's limits) or the damping (outside 0..1); the returned
        command holds the clipped values.

        Raises:
            InvalidCommandError: on the next cycle, if ``command`` holds
                non-finite values (the world refuses them).
        """
        if not self._open:  # requires_open, inline (every cycle)
            raise NotConnectedError(f"{_WHAT}: send() before connect/start")
        fri = self._fri
        msr = self._msr
        if command is not None and msr.state == _CMD and msr.power != 0:
            # to_fri_command's Cartesian impedance command, inline (the same writes)
            fri.flags = CARTESIAN_FLAGS
            fri.control = _CART_IMPEDANCE
            fri.cart_pos[...] = command.pose_m
            fri.add_tcp_ft[...] = command.wrench_n_nm
            fri.cart_stiffness[...] = command.stiffness_npm_nmprad
            fri.cart_damping[...] = command.damping_ratio
            status = _APPLIED
            flags = _CARTESIAN
        else:
            status = to_fri_command(command, msr, fri)
            flags = int(fri.flags)
        self._answered = True
        slots = self._slots
        if slots and not self.wire_precision:
            # with a delay, what the KRC takes if it takes this answer (_advance): a copy
            # in the slot after the last one taken (no command in flight holds it), and
            # its arm command (_arm_command(slot, k), kept while its key stays); done
            # here, where the arrays were just written
            k = self._slot + 1
            if k == len(slots):
                k = 0
            buf, slot = slots[k]
            buf[...] = self._fri_buf
            slot.flags = f = fri.flags
            slot.control = c = fri.control
            mode = self.world.mode
            kept = self._slot_arms[k]
            if kept is not None and kept[0] is f and kept[1] is c and kept[2] is mode:
                self._pending = kept[3]
            else:
                arm = self._pending = self._arm_command(slot, k)
                self._slot_arms[k] = (f, c, mode, arm)
        # applied_from_fri without a copy: the applied command is one of a few views of
        # the FRI command's arrays (the same values: the set-point, the gains, the
        # wrench or zeros), or of the clipped gains
        applied = self._applied
        applied.status = status
        applied.extras = fri
        if flags & _CARTSTIFF:
            # the gains rarely change: clip them again only when their bytes do
            key = self._gain_values.tobytes()  # the stiffness and the damping
            gains = self._gains
            if gains is None or gains[0] != key:
                gains = self._gains = (key, self._clipped_commands(fri))
            clipped = gains[1]
            if clipped is not None:
                applied.status = status | ApplyStatus.CLIPPED
                applied.command = clipped[0] if flags & _TCPFT else clipped[1]
                return applied
        applied.command = self._as_sent if flags & _TCPFT else self._as_sent_no_wrench
        return applied

    def _clipped_commands(self, fri: FriCommand
                          ) -> tuple[CartesianCommand, CartesianCommand] | None:
        """The applied commands (with the wrench sent, with none) of the stiffness and
        damping the world will apply, or ``None`` if neither clips."""
        mx = self.world.scene.controller.cart_stiffness_max
        k, clipped = clip_cart_stiffness(fri.cart_stiffness, mx[0], mx[1])
        d = np.clip(fri.cart_damping, 0.0, 1.0)
        if clipped or bool(np.any(d != fri.cart_damping)):
            k.flags.writeable = d.flags.writeable = False
            return (CartesianCommand(fri.cart_pos, k, d, fri.add_tcp_ft),
                    CartesianCommand(fri.cart_pos, k, d, _NO_WRENCH))
        return None


def _stop_message(error: int, q: np.ndarray, limits_rad: np.ndarray) -> str:
    joints = ", ".join(
        f"A{i + 1} reached its software limit switch at {np.degrees(q[i]):+.1f} deg "
        f"(limit +-{np.degrees(limits_rad[i]):.1f} deg)"
        for i in range(7) if error & (1 << i)
    )
    return (f"KRC stopped the robot: {joints}; FRI left command mode "
            f"(error 0x{error:02x}), the arm is held")


def open_sim(
    scene: Scene | Path | str,
    seed: int | None = None,
    overrides: Iterable[str] = (),
    max_cycles: int | None = None,
    start_cycles: int = 100,
    software_limits_deg: Sequence[float] = SOFTWARE_LIMITS_DEG,
) -> tuple[SimRobot, SimFtSensor]:
    """Build a world from a scene (object or TOML path) and its robot/sensor pair."""
    if not isinstance(scene, Scene):
        scene = load_scene(Path(scene), overrides)
    world = SimWorld(scene, seed=seed)
    robot = SimRobot(world, max_cycles=max_cycles, start_cycles=start_cycles,
                     software_limits_deg=software_limits_deg)
    return robot, SimFtSensor(world)


def open_rig_robot(cfg: SimRobotConfig, ctx: OpenContext, path: Path, scene: Scene) -> OpenedRobot:
    """The ``sim`` robot of a rig: :class:`SimRobot` on a world of ``scene`` (read from
    ``path``), with its run metadata and the scene file attached."""
    world = SimWorld(scene, seed=ctx.seed)
    robot = SimRobot(world, start_cycles=cfg.start_cycles,
                     max_consecutive_misses=cfg.max_consecutive_misses,
                     wire_precision=cfg.wire_precision)
    meta = {
        "driver": "sim",
        "scene_file": str(path),
        "scene_json": scene.model_dump_json(),
        "wire_precision": str(cfg.wire_precision).lower(),
    }
    return OpenedRobot(robot, lambda: world.cycle * world.cycle_ns, None, meta,
                       [(path.name, path.read_bytes())], scene=scene)
