"""Robot-neutral state and command <-> FRI packet contents: the one rule every FRI robot uses.

Pure functions, no I/O: the UDP driver (:class:`~drivers.fri.driver.FriRobot`),
the in-process simulated robot and the KRC emulator all turn a
:class:`~drivers.base.types.CartesianCommand` into the
:class:`~drivers.fri.types.FriCommand` the KRC gets with
:func:`to_fri_command`, so the three send the same bytes for the same cycle.

The rule (FRI 1.x: while the KRC is not commanding, the remote must echo the
KRC's own commanded position, or entering command mode jumps):

* no command (``None``): mirror, status :attr:`~ApplyStatus.HELD`;
* the KRC is not commanding (state not CMD, or drives off: ``power == 0``):
  mirror, status :attr:`~ApplyStatus.MIRRORED`;
* otherwise a Cartesian impedance command (flags CARTPOS | TCPFT | CARTSTIFF |
  CARTDAMP, strategy CART_IMPEDANCE), status :attr:`~ApplyStatus.APPLIED`.

A mirror is :meth:`FriCommand.hold`: flags JNTPOS | CARTPOS, ``jntPos =
cmdJntPos + cmdJntPosFriOffset``, ``cartPos = cmdCartPos``, the KRC's own
control mode. Fields the flags do not select keep their previous value
(the KRC ignores them), except that a mirror of a given command carries that
command's wrench and gains, and a mirror of no command carries a zero wrench
(so that the bytes equal what the pre-split runner and driver sent).
"""

from __future__ import annotations

from typing import Final

import numpy as np

from drivers.base.types import (
    AppliedCommand,
    ApplyStatus,
    CartesianCommand,
    LinkHealth,
    RobotState,
)
from drivers.fri.types import (
    CmdFlags,
    ControlMode,
    FriCommand,
    FriMeasurement,
    FriQuality,
    FriState,
)

__all__ = [
    "CARTESIAN_FLAGS",
    "MIRROR_FLAGS",
    "applied_from_fri",
    "commanding",
    "copy_fri_command",
    "mirror_into",
    "robot_state_from_fri",
    "to_fri_command",
]

#: Flags of a Cartesian impedance command.
CARTESIAN_FLAGS: Final = CmdFlags.CARTPOS | CmdFlags.TCPFT | CmdFlags.CARTSTIFF | CmdFlags.CARTDAMP
#: Flags of a mirror (:meth:`FriCommand.hold`).
MIRROR_FLAGS: Final = CmdFlags.JNTPOS | CmdFlags.CARTPOS
_TCPFT: Final = int(CmdFlags.TCPFT)  # ``int & IntFlag`` goes through the enum machinery
_new: Final = object.__new__
_CMD: Final = FriState.CMD


def commanding(msr: FriMeasurement) -> bool:
    """The KRC takes commands this cycle: state CMD and drives on."""
    return msr.state == FriState.CMD and msr.power != 0


def mirror_into(msr: FriMeasurement, out: FriCommand) -> None:
    """Make ``out`` a mirror of the KRC (:meth:`FriCommand.hold`), in place."""
    out.flags = MIRROR_FLAGS
    out.control = msr.control
    np.add(msr.cmd_jnt_pos, msr.cmd_jnt_pos_fri_offset, out=out.jnt_pos)
    out.cart_pos[...] = msr.cmd_cart_pos


def to_fri_command(
    cmd: CartesianCommand | None, msr: FriMeasurement, out: FriCommand
) -> ApplyStatus:
    """Fill ``out`` (in place, no allocation) with what the KRC gets for ``cmd`` this cycle.

    ``msr`` is this cycle's measurement. Returns how ``cmd`` was applied (see
    the module docstring). ``cmd`` is copied, never kept.
    """
    if cmd is None:
        mirror_into(msr, out)
        out.add_tcp_ft[...] = 0.0
        return ApplyStatus.HELD
    if msr.state != _CMD or msr.power == 0:  # not commanding(msr)
        mirror_into(msr, out)
        out.add_tcp_ft[...] = cmd.wrench_n_nm
        out.cart_stiffness[...] = cmd.stiffness_npm_nmprad
        out.cart_damping[...] = cmd.damping_ratio
        return ApplyStatus.MIRRORED
    out.flags = CARTESIAN_FLAGS
    out.control = ControlMode.CART_IMPEDANCE
    out.cart_pos[...] = cmd.pose_m
    out.add_tcp_ft[...] = cmd.wrench_n_nm
    out.cart_stiffness[...] = cmd.stiffness_npm_nmprad
    out.cart_damping[...] = cmd.damping_ratio
    return ApplyStatus.APPLIED


def applied_from_fri(out: FriCommand, status: ApplyStatus, dst: AppliedCommand) -> AppliedCommand:
    """Fill ``dst`` (in place) with what the KRC applies for ``out``; returns ``dst``.

    ``dst.command`` gets the set-point ``out.cart_pos``, the gains of ``out``
    (for a mirror: the gains last sent, which the KRC keeps) and ``out``'s
    wrench when TCPFT is selected (a mirror applies none: zero).
    ``dst.extras`` is ``out`` itself (not copied).
    """
    c = dst.command
    c.pose_m[...] = out.cart_pos
    c.stiffness_npm_nmprad[...] = out.cart_stiffness
    c.damping_ratio[...] = out.cart_damping
    if int(out.flags) & _TCPFT:
        c.wrench_n_nm[...] = out.add_tcp_ft
    else:
        c.wrench_n_nm.fill(0.0)
    dst.status = status
    dst.extras = out
    return dst


def copy_fri_command(src: FriCommand, dst: FriCommand) -> None:
    """Copy every field of ``src`` into ``dst`` (no allocation)."""
    dst.flags = src.flags
    dst.control = src.control
    dst.jnt_pos[...] = src.jnt_pos
    dst.cart_pos[...] = src.cart_pos
    dst.add_jnt_trq[...] = src.add_jnt_trq
    dst.add_tcp_ft[...] = src.add_tcp_ft
    dst.jnt_stiffness[...] = src.jnt_stiffness
    dst.jnt_damping[...] = src.jnt_damping
    dst.cart_stiffness[...] = src.cart_stiffness
    dst.cart_damping[...] = src.cart_damping
    dst.krl_real[...] = src.krl_real
    dst.krl_int[...] = src.krl_int
    dst.krl_bool = src.krl_bool


def robot_state_from_fri(m: FriMeasurement, dst: RobotState | None = None) -> RobotState:
    """The robot-neutral view of a measurement (``dst`` filled in place when given).

    Arrays are shared with ``m``, not copied (``m`` is ``extras``); ``truth``
    is ``None`` (a simulator's caller sets it). The cycle time is the KRC's
    command sample time (its measurement sample time when that is not set).
    """
    if dst is None:
        # a new state without the dataclass's __init__ (its default pose and joints
        # would be built only to be replaced): every field set here, in field order
        dst = _new(RobotState)
        dst.time_ns = m.time_ns
        dst.tcp_pose_m = m.msr_cart_pos
        dst.joint_pos_rad = m.msr_jnt_pos
        dst.link = link = _new(LinkHealth)
    else:
        dst.time_ns = m.time_ns
        dst.tcp_pose_m = m.msr_cart_pos
        dst.joint_pos_rad = m.msr_jnt_pos
        link = dst.link
    link.commanding = m.state == FriState.CMD
    link.healthy = m.quality > FriQuality.UNACCEPTABLE
    link.cycle = m.seq
    link.cycle_s = m.cmd_sample_time if m.cmd_sample_time > 0.0 else m.msr_sample_time
    dst.tcp_twist_mps_radps = None
    dst.ext_wrench_n_nm = m.est_ext_tcp_ft
    dst.truth = None
    dst.extras = m
    return dst
