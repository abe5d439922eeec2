"""A UR e-Series controller running ffexp's URScript program on the simulated world (no sockets).

:class:`UrSimController` is what both the RTDE emulator (``ffexp emulate --robot
ur5e``, :mod:`drivers.emulate.session`) and the in-process lockstep UR
(:mod:`drivers.ur.emulate.lockstep`) run: :meth:`~UrSimController.take` latches
the input registers a client wrote, :meth:`~UrSimController.step` runs one
control cycle (``scene.fri.cycle``, 2 ms for a UR) and returns the RTDE outputs
of its end, name -> value.

The program's semantics are those of ``drivers/ur/ffexp_control.script``
(register map: :mod:`drivers.ur.registers`): mode hold, pose servo, force mode
with the selection bits (the arm's law: :mod:`drivers.ur.emulate.control`) or end;
a sequence number unchanged for :data:`STALE_CYCLES` cycles holds the arm
(script state 3) until a new one comes; the applied sequence number and the
script state go to the output registers. After an end request the program is
over (state 2) until commands come again, when the emulator starts it anew (as
``script = "send"`` does on a real controller at connect).

A protective stop (a joint at its position or speed limit,
:class:`~drivers.ur.emulate.control.UrArmControl`) sets ``safety_mode``
PROTECTIVE_STOP and the ``protective_stopped`` bit of ``safety_status_bits``;
the arm is held. ``actual_TCP_force`` is the wrench the environment exerts on
the tool, from the simulated F/T sensor's newest sample of the cycle (its
noise, bias and delay: the scene's ``ft_sensor``), in the base frame like a
UR's; ``ft_raw_wrench`` the same sample in the sensor (tool) frame.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Final

import numpy as np

from drivers.ur import registers
from drivers.ur.emulate.control import ForceModeCommand, UrArmControl
from drivers.ur.registers import Mode, ScriptState
from drivers.ur.rtde.variables import SAFETY_STATUS_BIT
from drivers.world.state import LazyArmState
from drivers.world.world import SimWorld

__all__ = ["STALE_CYCLES", "UrSimController"]

#: Cycles without a new sequence number before the program holds the arm (the script's).
STALE_CYCLES: Final = 25
ROBOT_MODE_RUNNING: Final = 7
SAFETY_NORMAL: Final = 1
SAFETY_PROTECTIVE_STOP: Final = 3
RUNTIME_PLAYING: Final = 2
_PROTECTIVE_BITS: Final = (1 << SAFETY_STATUS_BIT["protective_stopped"]) | (
    1 << SAFETY_STATUS_BIT["stopped_due_to_safety"])
_NORMAL_BITS: Final = 1 << SAFETY_STATUS_BIT["normal_mode"]
#: Each input register's place in :data:`~drivers.ur.registers.INPUT_NAMES`.
_PLACE: Final = {name: i for i, name in enumerate(registers.INPUT_NAMES)}
_SEQ, _MODE, _SELECTION = (_PLACE[n] for n in (registers.SEQ, registers.MODE,
                                               registers.SELECTION))
_POSE, _WRENCH, _LIMITS = (slice(_PLACE[n[0]], _PLACE[n[-1]] + 1)
                           for n in (registers.POSE, registers.WRENCH, registers.LIMITS))
_DAMPING, _GAIN = _PLACE[registers.DAMPING], _PLACE[registers.GAIN_SCALING]


class UrSimController:
    """ffexp's URScript program on ``world`` (module docstring)."""

    def __init__(self, world: SimWorld) -> None:
        self.world = world
        self.arm = UrArmControl(world)
        # the program's input registers in INPUT_NAMES order (zero until written), and
        # any other input written
        self._regs: list[Any] = [0] * len(registers.INPUT_NAMES)
        self._other: dict[str, Any] = {}
        # the world's end state the outputs were made of, held until the next cycle: the
        # arm's next command and the driver's truth read the same object, computed once
        # (SimWorld.last_state: the same object while someone holds it)
        self._state: LazyArmState | None = None
        self.script_state = ScriptState.RUNNING
        self.applied_seq = 0
        self._last_seq = 0
        self._stale = 0
        self._force = np.zeros(6)
        self._sensor_wrench = np.zeros(6)
        self.steps = 0

    @property
    def inputs(self) -> dict[str, Any]:
        """The input registers as last written (the program's are zero until written)."""
        return {**self._other, **dict(zip(registers.INPUT_NAMES, self._regs, strict=True))}

    def take(self, values: Mapping[str, Any]) -> None:
        """Latch input registers (a client's input data package)."""
        regs, place = self._regs, _PLACE
        for name, value in values.items():
            i = place.get(name)
            if i is None:
                self._other[name] = value
            else:
                regs[i] = value

    def take_program_inputs(self, values: tuple[Any, ...]) -> None:
        """Latch every register of :data:`~drivers.ur.registers.INPUT_NAMES` at once,
        ``values`` in that order (the in-process link's whole input record)."""
        self._regs[:] = values

    def _program(self) -> ForceModeCommand | None:
        """One cycle of ffexp_control.script: the arm's command (``None``: hold)."""
        regs = self._regs
        seq, mode = int(regs[_SEQ]), int(regs[_MODE])
        if self.script_state == ScriptState.ENDED:
            if mode == Mode.END or seq == self._last_seq:
                return None
            self.script_state = ScriptState.RUNNING  # started anew
        if mode == Mode.END:
            self.script_state = ScriptState.ENDED
            return None
        if seq == self._last_seq:
            self._stale += 1
        else:
            self._stale, self._last_seq = 0, seq
        if self._stale >= STALE_CYCLES or mode == Mode.HOLD:
            if self._stale >= STALE_CYCLES:
                self.script_state = ScriptState.HELD_STALE
            self.applied_seq = seq
            return None
        self.script_state = ScriptState.RUNNING
        self.applied_seq = seq
        pose = registers.pose_matrix(np.array(regs[_POSE], dtype=np.float64))
        if mode != Mode.FORCE:
            return ForceModeCommand(pose)
        return ForceModeCommand(pose, registers.selection_axes(int(regs[_SELECTION])),
                                np.array(regs[_WRENCH], dtype=np.float64),
                                np.array(regs[_LIMITS], dtype=np.float64),
                                float(regs[_DAMPING]), float(regs[_GAIN]))

    def step(self) -> dict[str, object]:
        """Run one control cycle with the latched registers; the outputs of its end."""
        self.world.advance(self.arm.command(self._program()))
        self.arm.check_limits()
        self.steps += 1
        return self.outputs()

    def outputs(self) -> dict[str, object]:
        """The RTDE outputs of the world's current state, name -> value."""
        w = self.world
        state = self._state = w.last_state
        pose = state.tcp_pose_m
        rot = pose[:3, :3]
        samples = w.ft_samples()
        if len(samples.time_ns):
            self._sensor_wrench = np.array(samples.wrench[-1], dtype=np.float64)
            s = self._sensor_wrench
            self._force = np.concatenate((rot @ s[:3], rot @ s[3:]))
        twist = self.arm.twist()
        stopped = self.arm.stopped is not None
        n = len(state.jnt_pos_rad)
        return {
            "timestamp": w.time,
            "actual_q": np.array(state.jnt_pos_rad[:6]),
            "actual_qd": np.array(w.arm_qvel[:n][:6]),
            "actual_TCP_pose": registers.pose_vector(pose),
            "actual_TCP_speed": np.concatenate((rot @ twist[:3], rot @ twist[3:])),
            "actual_TCP_force": self._force.copy(),
            "ft_raw_wrench": self._sensor_wrench.copy(),
            "robot_mode": ROBOT_MODE_RUNNING,
            "safety_mode": SAFETY_PROTECTIVE_STOP if stopped else SAFETY_NORMAL,
            "safety_status_bits": _PROTECTIVE_BITS if stopped else _NORMAL_BITS,
            "runtime_state": RUNTIME_PLAYING,
            registers.APPLIED_SEQ: self.applied_seq,
            registers.SCRIPT_STATE: int(self.script_state),
        }
