"""libfranka's wire layout (server version 10, libfranka 0.21): byte offsets and sizes as the
protocol defines them (packed, little-endian), checked by hand-computed offsets and by
packing values with struct independently of the numpy dtypes."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from drivers.franka import codec


def test_the_state_record_is_packed_float32_with_the_accelerometers() -> None:
    st = codec.ROBOT_STATE
    # u64 id, six 4x4 poses of float32
    assert st.fields["message_id"][1] == 0
    assert st.fields["O_T_EE"][1] == 8
    assert st.fields["NE_T_EE"][1] == 8 + 5 * 64
    # m_ee at 392, then I_ee[9], F_x_Cee[3], m_load, I_load[9], F_x_Cload[3], elbow[2],
    # elbow_d[2], tau_J, tau_J_d, dtau_J: q after 8 + 96*4 + 1+9+3+1+9+3+2+2 + 3*7 floats
    assert st.fields["q"][1] == 8 + 4 * (96 + 30 + 21)
    assert st.fields["dq"][1] == st.fields["q"][1] + 2 * 28
    assert st.fields["motion_generator_mode"][1] == 8 + 4 * 320  # 284 floats + 36 accel
    assert st.fields["errors"][1] == st.fields["motion_generator_mode"][1] + 2
    assert st.fields["reflex_reason"][1] == st.fields["errors"][1] + 41
    assert st.fields["control_command_success_rate"][1] == st.itemsize - 4
    assert st.itemsize == 1377  # what pylibfranka 0.21.3 reads (measured)


def test_a_state_encodes_as_struct_packs_it() -> None:
    rec = np.zeros((), dtype=codec.ROBOT_STATE)
    rec["message_id"] = 0x0102030405060708
    rec["q"] = np.arange(7) * 0.25
    rec["robot_mode"] = codec.RobotMode.MOVE
    rec["errors"][31] = 1  # communication_constraints_violation
    rec["control_command_success_rate"] = 0.75
    data = rec.tobytes()
    assert data[:8] == struct.pack("<Q", 0x0102030405060708)
    q_at = 8 + 4 * 147
    assert data[q_at:q_at + 28] == struct.pack("<7f", *(np.arange(7) * 0.25))
    assert data[1372] == int(codec.RobotMode.MOVE)
    assert data[1290 + 31] == 1
    assert struct.unpack("<f", data[-4:]) == (0.75,)
    back = codec.decode(codec.ROBOT_STATE, data)
    assert codec.error_names(back["errors"]) == ["communication_constraints_violation"]


def test_the_command_record_carries_doubles_and_the_torques_at_314() -> None:
    cmd = codec.ROBOT_COMMAND
    assert cmd.itemsize == 8 + 38 * 8 + 2 + 7 * 8 + 1 == 371
    rec = np.zeros((), dtype=cmd)
    rec["message_id"] = 42
    rec["tau_J_d"] = [1.5, -2.0, 0, 0, 0, 0, 0.125]
    rec["motion_generation_finished"] = 1
    data = rec.tobytes()
    assert data[314:314 + 56] == struct.pack("<7d", 1.5, -2.0, 0, 0, 0, 0, 0.125)
    assert data[313] == 1 and data[370] == 0


def test_tcp_messages_carry_their_size_in_the_header() -> None:
    data = codec.message(codec.CONNECT_RESPONSE, codec.Command.CONNECT, 7,
                         status=int(codec.ConnectStatus.INCOMPATIBLE_LIBRARY_VERSION), version=9)
    assert data == struct.pack("<III", 0, 7, 15) + bytes([1]) + struct.pack("<H", 9)
    req = struct.pack("<IIIHH", 0, 3, 16, 10, 50000)
    rec = codec.decode(codec.CONNECT_REQUEST, req)
    assert (int(rec["version"]), int(rec["udp_port"])) == (10, 50000)
    assert codec.MOVE_REQUEST.itemsize == 12 + 4 + 4 + 2 * 24
    assert codec.MOVE_RESPONSE.itemsize == 13
    assert int(codec.header_of(req)["size"]) == 16


def test_a_record_of_the_wrong_size_is_refused() -> None:
    with pytest.raises(ValueError, match="1376 bytes"):
        codec.decode(codec.ROBOT_STATE, bytes(1376))


def test_the_error_flags_are_named_in_the_protocols_order() -> None:
    assert len(codec.ERROR_NAMES) == 41 == len(set(codec.ERROR_NAMES))
    assert codec.ERROR_NAMES[0] == "joint_position_limits_violation"
    assert codec.ERROR_NAMES[31] == "communication_constraints_violation"
    assert codec.ERROR_NAMES[-1] == "base_acceleration_invalid_reading"


def test_a_state_read_from_its_record_names_its_flags_and_follows_its_tool() -> None:
    from drivers.franka.link import state_from_record

    rec = np.zeros((), dtype=codec.ROBOT_STATE)
    tool = np.eye(4)
    tool[:3, 3] = (0.01, -0.02, 0.2)
    rec["F_T_EE"] = tool.ravel(order="F")
    first = state_from_record(codec.decode(codec.ROBOT_STATE, rec.tobytes()))
    assert first.errors == [] and first.reflex == []
    assert first.f_t_ee.tolist() == tool.astype(np.float32).astype(np.float64).tolist()
    assert not first.f_t_ee.flags.writeable  # (kept for the next states: not to be changed)
    rec["errors"][codec.ERROR_NAMES.index("joint_velocity_violation")] = 1
    rec["reflex_reason"][[0, 3]] = 1
    tool[2, 3] = 0.25  # another tool
    rec["F_T_EE"] = tool.ravel(order="F")
    second = state_from_record(codec.decode(codec.ROBOT_STATE, rec.tobytes()))
    assert second.errors == ["joint_velocity_violation"]
    assert second.reflex == [codec.ERROR_NAMES[0], codec.ERROR_NAMES[3]]
    assert second.f_t_ee[2, 3] == np.float32(0.25)
    assert first.f_t_ee[2, 3] == np.float32(0.2)
