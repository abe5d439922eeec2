"""The one rule that turns a neutral command into the FRI command (drivers/fri/command.py)."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.base.types import AppliedCommand, ApplyStatus, CartesianCommand, RobotState
from drivers.fri.codec import CmdArrays, encode_cmd
from drivers.fri.command import (
    applied_from_fri,
    copy_fri_command,
    robot_state_from_fri,
    to_fri_command,
)
from drivers.fri.convert import command_to_arrays
from drivers.fri.types import (
    CmdFlags,
    ControlMode,
    FriCommand,
    FriMeasurement,
    FriQuality,
    FriState,
)


def _msr(state: FriState = FriState.CMD, **kw: object) -> FriMeasurement:
    m = FriMeasurement(state=state, control=ControlMode.JOINT_IMPEDANCE, **kw)  # type: ignore[arg-type]
    m.cmd_jnt_pos[:] = np.arange(7) * 0.1
    m.cmd_jnt_pos_fri_offset[:] = 0.01
    m.cmd_cart_pos[:3, 3] = [0.4, -0.1, 0.6]
    m.msr_cart_pos[:3, 3] = [0.41, -0.11, 0.61]
    return m


def _cmd() -> CartesianCommand:
    c = CartesianCommand()
    c.pose_m[:3, 3] = [0.5, 0.2, 0.3]
    c.stiffness_npm_nmprad[:] = [1000, 1100, 1200, 100, 110, 120]
    c.damping_ratio[:] = [0.7, 0.6, 0.5, 0.4, 0.3, 0.2]
    c.wrench_n_nm[:] = [1, 2, 3, 0.1, 0.2, 0.3]
    return c


def _wire(c: FriCommand) -> bytes:
    a = CmdArrays()
    command_to_arrays(c, a)
    return encode_cmd(a)


def test_applied_in_command_mode_takes_every_cartesian_field() -> None:
    m, c, out = _msr(), _cmd(), FriCommand()
    out.jnt_pos[:] = 9.0  # not selected: left alone
    assert to_fri_command(c, m, out) is ApplyStatus.APPLIED
    assert out.flags == CmdFlags.CARTPOS | CmdFlags.TCPFT | CmdFlags.CARTSTIFF | CmdFlags.CARTDAMP
    assert out.control == ControlMode.CART_IMPEDANCE
    np.testing.assert_array_equal(out.cart_pos, c.pose_m)
    np.testing.assert_array_equal(out.add_tcp_ft, c.wrench_n_nm)
    np.testing.assert_array_equal(out.cart_stiffness, c.stiffness_npm_nmprad)
    np.testing.assert_array_equal(out.cart_damping, c.damping_ratio)
    np.testing.assert_array_equal(out.jnt_pos, 9.0)


def test_the_command_is_copied_not_kept() -> None:
    m, c, out = _msr(), _cmd(), FriCommand()
    to_fri_command(c, m, out)
    c.pose_m[:] = 0.0
    c.wrench_n_nm[:] = -5.0
    assert out.cart_pos[0, 3] == 0.5 and out.add_tcp_ft[0] == 1.0


@pytest.mark.parametrize(
    ("cmd", "state", "status"),
    [
        (None, FriState.CMD, ApplyStatus.HELD),
        (None, FriState.MON, ApplyStatus.HELD),
        ("given", FriState.MON, ApplyStatus.MIRRORED),
        ("given", FriState.OFF, ApplyStatus.MIRRORED),
    ],
)
def test_mirror_is_fri_command_hold(cmd: str | None, state: FriState, status: ApplyStatus) -> None:
    m, out = _msr(state), FriCommand()
    assert to_fri_command(_cmd() if cmd else None, m, out) is status
    hold = FriCommand.hold(m)
    assert out.flags == hold.flags == CmdFlags.JNTPOS | CmdFlags.CARTPOS
    assert out.control == hold.control == ControlMode.JOINT_IMPEDANCE
    np.testing.assert_array_equal(out.jnt_pos, np.arange(7) * 0.1 + 0.01)
    np.testing.assert_array_equal(out.cart_pos, m.cmd_cart_pos)


def test_drives_off_in_command_state_mirrors() -> None:
    m = _msr(FriState.CMD, power=0)
    assert to_fri_command(_cmd(), m, FriCommand()) is ApplyStatus.MIRRORED


def test_hold_bytes_equal_the_old_connect_phase_command() -> None:
    """No command: the datagram is FriCommand.hold's (zero wrench, gains as last sent)."""
    m, out = _msr(FriState.MON), FriCommand()
    to_fri_command(None, m, out)
    assert _wire(out) == _wire(FriCommand.hold(m))


def test_mirror_of_a_command_keeps_its_gains_on_the_wire_but_not_the_flags() -> None:
    """Like the old driver: positions mirrored, unselected fields from the runner's command."""
    m, c, out = _msr(FriState.MON), _cmd(), FriCommand()
    to_fri_command(c, m, out)
    ref = FriCommand.hold(m)
    ref.add_tcp_ft[:] = c.wrench_n_nm
    ref.cart_stiffness[:] = c.stiffness_npm_nmprad
    ref.cart_damping[:] = c.damping_ratio
    assert _wire(out) == _wire(ref)


def test_applied_from_fri_reports_what_the_robot_gets() -> None:
    m, c, out = _msr(), _cmd(), FriCommand()
    dst = AppliedCommand()
    st = to_fri_command(c, m, out)
    assert applied_from_fri(out, st, dst) is dst
    assert dst.status is ApplyStatus.APPLIED and dst.extras is out
    np.testing.assert_array_equal(dst.command.pose_m, c.pose_m)
    np.testing.assert_array_equal(dst.command.wrench_n_nm, c.wrench_n_nm)
    np.testing.assert_array_equal(dst.command.stiffness_npm_nmprad, c.stiffness_npm_nmprad)
    # then the link drops to monitor mode and the runner sends nothing: the
    # robot holds its own set-point with the gains last sent, and no wrench
    m2 = _msr(FriState.MON)
    st = to_fri_command(None, m2, out)
    applied_from_fri(out, st, dst)
    assert dst.status is ApplyStatus.HELD
    np.testing.assert_array_equal(dst.command.pose_m, m2.cmd_cart_pos)
    np.testing.assert_array_equal(dst.command.wrench_n_nm, np.zeros(6))
    np.testing.assert_array_equal(dst.command.stiffness_npm_nmprad, c.stiffness_npm_nmprad)
    np.testing.assert_array_equal(dst.command.damping_ratio, c.damping_ratio)


@pytest.mark.parametrize(
    ("state", "quality", "commanding", "healthy"),
    [
        (FriState.CMD, FriQuality.PERFECT, True, True),
        (FriState.CMD, FriQuality.BAD, True, True),
        (FriState.MON, FriQuality.OK, False, True),
        (FriState.CMD, FriQuality.UNACCEPTABLE, True, False),
        (FriState.OFF, FriQuality.INVALID, False, False),
    ],
)
def test_robot_state_link_health(
    state: FriState, quality: FriQuality, commanding: bool, healthy: bool
) -> None:
    m = _msr(state, quality=quality, seq=70000, time_ns=123)
    s = robot_state_from_fri(m)
    assert s.link.commanding is commanding and s.link.healthy is healthy
    assert s.link.cycle == 70000 and s.time_ns == 123


def test_robot_state_fields_and_reuse() -> None:
    m = _msr(cmd_sample_time=0.002, msr_sample_time=0.004)
    m.est_ext_tcp_ft[:] = [1, 2, 3, 4, 5, 6]
    dst = RobotState()
    dst.truth = object()  # type: ignore[assignment]
    s = robot_state_from_fri(m, dst)
    assert s is dst and s.extras is m and s.truth is None
    np.testing.assert_array_equal(s.tcp_pose_m, m.msr_cart_pos)
    np.testing.assert_array_equal(s.joint_pos_rad, m.msr_jnt_pos)
    np.testing.assert_array_equal(s.ext_wrench_n_nm, [1, 2, 3, 4, 5, 6])  # type: ignore[arg-type]
    assert s.link.cycle_s == 0.002
    m.cmd_sample_time = 0.0
    assert robot_state_from_fri(m).link.cycle_s == 0.004


def test_copy_fri_command_copies_every_field_into_its_own_arrays() -> None:
    src, dst = FriCommand(), FriCommand()
    to_fri_command(_cmd(), _msr(), src)
    src.krl_int[3], src.krl_real[2], src.krl_bool = 7, 1.5, 3
    src.jnt_stiffness[:] = 42.0
    copy_fri_command(src, dst)
    assert _wire(dst) == _wire(src)
    src.cart_pos[0, 3] = -1.0
    assert dst.cart_pos[0, 3] == 0.5 and dst.krl_int[3] == 7 and dst.krl_bool == 3
