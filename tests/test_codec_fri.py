"""Tests of the FRI 1.x codec (drivers.fri.codec).

Expected offsets, sizes and struct formats are copied from the fact sheet
(shared/research/fri_netft.md, tables "tFriMsrData" / "tFriCmdData"), not from
the dtypes under test. Conversion examples are worked out by hand in comments.
"""

from __future__ import annotations

import re
import struct
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from drivers.errors import DriverError, MalformedPacketError, PacketEncodeError
from drivers.fri import codec as c

# --------------------------------------------------------------------------- fact sheet

# (path, byte offset, wire type, element count) from the fact sheet's tables.
MSR_TABLE = [
    ("head.sendSeqCount", 0, "<u2", 1),
    ("head.reflSeqCount", 2, "<u2", 1),
    ("head.packetSize", 4, "<u2", 1),
    ("head.datagramId", 6, "<u2", 1),
    ("krl.realData", 8, "<f4", 16),
    ("krl.intData", 72, "<i4", 16),
    ("krl.boolData", 136, "<u2", 1),
    ("krl.fill", 138, "<u2", 1),
    ("intf.timestamp", 140, "<f4", 1),
    ("intf.state", 144, "<u2", 1),
    ("intf.quality", 146, "<u2", 1),
    ("intf.desiredMsrSampleTime", 148, "<f4", 1),
    ("intf.desiredCmdSampleTime", 152, "<f4", 1),
    ("intf.safetyLimits", 156, "<f4", 1),
    ("intf.stat.answerRate", 160, "<f4", 1),
    ("intf.stat.latency", 164, "<f4", 1),
    ("intf.stat.jitter", 168, "<f4", 1),
    ("intf.stat.missRate", 172, "<f4", 1),
    ("intf.stat.missCounter", 176, "<u4", 1),
    ("robot.power", 180, "<u2", 1),
    ("robot.control", 182, "<u2", 1),
    ("robot.error", 184, "<u2", 1),
    ("robot.warning", 186, "<u2", 1),
    ("robot.temperature", 188, "<f4", 7),
    ("data.msrJntPos", 216, "<f4", 7),
    ("data.msrCartPos", 244, "<f4", 12),
    ("data.cmdJntPos", 292, "<f4", 7),
    ("data.cmdJntPosFriOffset", 320, "<f4", 7),
    ("data.cmdCartPos", 348, "<f4", 12),
    ("data.cmdCartPosFriOffset", 396, "<f4", 12),
    ("data.msrJntTrq", 444, "<f4", 7),
    ("data.estExtJntTrq", 472, "<f4", 7),
    ("data.estExtTcpFT", 500, "<f4", 6),
    ("data.jacobian", 524, "<f4", 42),
    ("data.massMatrix", 692, "<f4", 49),
    ("data.gravity", 888, "<f4", 7),
]
CMD_TABLE = [
    ("head.sendSeqCount", 0, "<u2", 1),
    ("head.reflSeqCount", 2, "<u2", 1),
    ("head.packetSize", 4, "<u2", 1),
    ("head.datagramId", 6, "<u2", 1),
    ("krl.realData", 8, "<f4", 16),
    ("krl.intData", 72, "<i4", 16),
    ("krl.boolData", 136, "<u2", 1),
    ("krl.fill", 138, "<u2", 1),
    ("cmd.cmdFlags", 140, "<u4", 1),
    ("cmd.jntPos", 144, "<f4", 7),
    ("cmd.cartPos", 172, "<f4", 12),
    ("cmd.addJntTrq", 220, "<f4", 7),
    ("cmd.addTcpFT", 248, "<f4", 6),
    ("cmd.jntStiffness", 272, "<f4", 7),
    ("cmd.jntDamping", 300, "<f4", 7),
    ("cmd.cartStiffness", 328, "<f4", 6),
    ("cmd.cartDamping", 352, "<f4", 6),
]
# Section sizes from the fact sheet (friComm *_SIZE macros).
MSR_SECTIONS = {"head": 8, "krl": 132, "intf": 40, "intf.stat": 20, "robot": 36, "data": 700}
CMD_SECTIONS = {"head": 8, "krl": 132, "cmd": 236}
# Python struct formats from the fact sheet.
MSR_FMT = "<HHHH16f16iHHfHHfffffffIHHHH7f7f12f7f7f12f12f7f7f6f42f49f7f"
CMD_FMT = "<HHHH16f16iHHI7f12f7f6f7f7f6f6f"


def field_info(dtype: np.dtype, path: str) -> tuple[int, np.dtype]:
    offset, sub = 0, dtype
    for part in path.split("."):
        sub, off = sub.fields[part][:2]
        offset += off
    return offset, sub


def leaf_values(record: np.ndarray, table: list[tuple[str, int, str, int]]) -> list[int]:
    """All leaf values in table order, floats as their uint32 bit patterns."""
    out: list[int] = []
    for path, _, wtype, _ in table:
        v = record
        for part in path.split("."):
            v = v[part]
        arr = np.asarray(v).reshape(-1)
        if wtype == "<f4":
            arr = arr.view("<u4")
        out.extend(int(x) for x in arr)
    return out


def bits_format(fmt: str) -> str:
    """Same layout with every float read as its uint32 bit pattern."""
    return fmt.replace("f", "I")


def codes(fmt: str) -> list[str]:
    """The format's item codes, one per value: "<HH2f" -> ["H", "H", "f", "f"]."""
    return [ch for n, ch in re.findall(r"(\d*)([a-zA-Z])", fmt) for _ in range(int(n or 1))]


def float_word_mask(table: list[tuple[str, int, str, int]], size: int) -> np.ndarray:
    mask = np.zeros(size // 4, dtype=bool)
    for _, off, wtype, n in table:
        if wtype == "<f4":
            mask[off // 4 : off // 4 + n] = True
    return mask


MSR_FLOAT_WORDS = float_word_mask(MSR_TABLE, 916)
CMD_FLOAT_WORDS = float_word_mask(CMD_TABLE, 376)


def random_packet(
    rng: np.random.Generator, size: int, ident: int, float_words: np.ndarray
) -> bytes:
    """Random valid packet: any ints, finite float32 (incl. -0 and subnormals) in float fields."""
    words = rng.integers(0, 2**32, size // 4, dtype=np.uint64).astype(np.uint32)
    exp_all_ones = (words & 0x7F800000) == 0x7F800000
    words[float_words & exp_all_ones] &= 0xBFFFFFFF  # clear one exponent bit: finite
    buf = bytearray(words.astype("<u4").tobytes())
    struct.pack_into("<HH", buf, 4, size, ident)
    return bytes(buf)


# --------------------------------------------------------------------------- layout


def test_sizes_match_fact_sheet() -> None:
    assert c.MSR_DTYPE.itemsize == 916 == c.MSR_SIZE
    assert c.CMD_DTYPE.itemsize == 376 == c.CMD_SIZE
    assert (c.MSR_DATAGRAM_ID, c.CMD_DATAGRAM_ID) == (0x2006, 0x1005)
    assert struct.calcsize(MSR_FMT) == 916 and struct.calcsize(CMD_FMT) == 376
    for name, size in MSR_SECTIONS.items():
        assert field_info(c.MSR_DTYPE, name)[1].itemsize == size, name
    for name, size in CMD_SECTIONS.items():
        assert field_info(c.CMD_DTYPE, name)[1].itemsize == size, name


@pytest.mark.parametrize(
    ("dtype", "table"), [(c.MSR_DTYPE, MSR_TABLE), (c.CMD_DTYPE, CMD_TABLE)], ids=["msr", "cmd"]
)
def test_field_offsets_and_types_match_fact_sheet(
    dtype: np.dtype, table: list[tuple[str, int, str, int]]
) -> None:
    covered = 0
    for path, offset, wtype, count in table:
        got_offset, sub = field_info(dtype, path)
        assert got_offset == offset, path
        base = sub.base if sub.subdtype is not None else sub
        assert base == np.dtype(wtype), path  # "<" pins little-endian on any host
        assert sub.itemsize == np.dtype(wtype).itemsize * count, path
        covered += sub.itemsize
    assert covered == dtype.itemsize  # the table covers every byte: no hidden padding


@pytest.mark.parametrize(
    ("dtype", "table", "fmt", "ident"),
    [
        (c.MSR_DTYPE, MSR_TABLE, MSR_FMT, 0x2006),
        (c.CMD_DTYPE, CMD_TABLE, CMD_FMT, 0x1005),
    ],
    ids=["msr", "cmd"],
)
def test_dtype_agrees_with_struct_format_on_random_packets(
    dtype: np.dtype, table: list[tuple[str, int, str, int]], fmt: str, ident: int
) -> None:
    rng = np.random.default_rng(20261122)
    size = struct.calcsize(fmt)
    for _ in range(200):
        raw = rng.integers(0, 256, size, dtype=np.uint8).tobytes()
        rec = np.frombuffer(raw, dtype).reshape(())
        assert leaf_values(rec, table) == list(struct.unpack(bits_format(fmt), raw))
    # and through the decoder, with a valid header
    raw = random_packet(rng, size, ident, float_word_mask(table, size))
    rec = c.decode_msr(raw) if ident == 0x2006 else c.decode_cmd(raw)
    assert leaf_values(rec, table) == list(struct.unpack(bits_format(fmt), raw))


# --------------------------------------------------------------------------- enums


def test_enum_values() -> None:
    assert {m.name: m.value for m in c.FriState} == {"INVALID": -1, "OFF": 0, "MON": 1, "CMD": 2}
    assert {m.name: m.value for m in c.FriQuality} == {
        "INVALID": -1,
        "UNACCEPTABLE": 0,
        "BAD": 1,
        "OK": 2,
        "PERFECT": 3,
    }
    assert {m.name: m.value for m in c.ControlMode} == {
        "OTHER": 0,
        "JOINT_POSITION": 1,
        "CART_IMPEDANCE": 2,
        "JOINT_IMPEDANCE": 3,
    }
    assert {m.name: m.value for m in c.CmdFlags} == {
        "JNTPOS": 0x0001,
        "JNTTRQ": 0x0004,
        "JNTSTIFF": 0x0010,
        "JNTDAMP": 0x0020,
        "CARTPOS": 0x0100,
        "TCPFT": 0x0400,
        "CARTSTIFF": 0x1000,
        "CARTDAMP": 0x2000,
    }


def test_enums_are_the_ones_of_drivers_fri_types() -> None:
    from drivers.fri import types as t

    assert c.FriState is t.FriState and c.FriQuality is t.FriQuality
    assert c.ControlMode is t.ControlMode and c.CmdFlags is t.CmdFlags


def test_the_split_codec_modules_are_one_api() -> None:
    """The codec package re-exports every public name of its parts, and they stay small."""
    from pathlib import Path

    from drivers.fri.codec import arrays, fields, layout, seq

    for mod in (arrays, fields, layout, seq):
        public = [n for n in vars(mod) if not n.startswith("_") and n.isidentifier()]
        for name in public:
            obj = getattr(mod, name)
            if getattr(obj, "__module__", mod.__name__) == mod.__name__ and name in c.__all__:
                assert getattr(c, name) is obj, name
        assert len(Path(mod.__file__ or "").read_text().splitlines()) <= 600
    assert set(c.__all__) <= set(vars(c))


def test_invalid_is_0xffff_on_the_wire_and_unknown_values_read_as_invalid() -> None:
    assert c.enum_to_wire(c.FriState.INVALID) == 0xFFFF
    assert c.enum_to_wire(c.FriQuality.INVALID) == 0xFFFF
    assert c.enum_to_wire(c.FriState.CMD) == 2
    assert c.fri_state_from_wire(0xFFFF) is c.FriState.INVALID
    assert c.fri_quality_from_wire(0xFFFF) is c.FriQuality.INVALID
    assert c.fri_state_from_wire(2) is c.FriState.CMD
    assert c.fri_quality_from_wire(3) is c.FriQuality.PERFECT
    assert c.fri_state_from_wire(7) is c.FriState.INVALID
    assert c.fri_quality_from_wire(0x8000) is c.FriQuality.INVALID
    assert c.fri_control_from_wire(3) is c.ControlMode.JOINT_IMPEDANCE
    assert c.fri_control_from_wire(99) is c.ControlMode.OTHER


@given(
    state=st.sampled_from(c.FriState),
    quality=st.sampled_from(c.FriQuality),
    control=st.sampled_from(c.ControlMode),
)
def test_enums_round_trip_through_a_packet(
    state: c.FriState, quality: c.FriQuality, control: c.ControlMode
) -> None:
    a = c.MsrArrays()
    a.state, a.quality, a.control = state, quality, control
    raw = c.encode_msr(a)
    assert struct.unpack_from("<HH", raw, 144) == (state & 0xFFFF, quality & 0xFFFF)
    assert struct.unpack_from("<H", raw, 182) == (control,)
    b = c.MsrArrays()
    assert c.decode_msr_into(raw, b) is c.DecodeStatus.OK
    assert (b.state, b.quality, b.control) == (state, quality, control)


# --------------------------------------------------------------------------- sequence counters


def test_seq_wraps_at_65535() -> None:
    assert c.seq_next(65535) == 0
    assert c.seq_next(0) == 1
    assert c.seq_delta(0, 65535) == 1
    assert c.seq_delta(65535, 0) == -1
    assert c.seq_delta(5, 5) == 0
    assert c.seq_delta(3, 65534) == 5  # 65534 -> 65535 -> 0 -> 1 -> 2 -> 3
    assert c.seq_delta(np.uint16(1), np.uint16(65535)) == 2
    assert c.classify_seq(0, 65535) == (c.SeqEvent.NEXT, 1)
    assert c.classify_seq(9, 9) == (c.SeqEvent.DUPLICATE, 0)
    assert c.classify_seq(1, 65534) == (c.SeqEvent.GAP, 3)
    assert c.classify_seq(65534, 1) == (c.SeqEvent.STALE, -3)


@given(old=st.integers(0, 65535), step=st.integers(-32768, 32767))
def test_seq_delta_inverts_wrapped_addition(old: int, step: int) -> None:
    assert c.seq_delta((old + step) % 65536, old) == step


# --------------------------------------------------------------------------- conversions


def test_frame_to_matrix_hand_example() -> None:
    # Rotation of +90 deg about z, translation (0.1, 0.2, 0.3); wire is row-major 3x4:
    # [r11 r12 r13 x, r21 r22 r23 y, r31 r32 r33 z].
    wire = [0, -1, 0, 0.1, 1, 0, 0, 0.2, 0, 0, 1, 0.3]
    t = c.frame_to_matrix(wire)
    assert t.shape == (4, 4)
    # The tool x axis (1, 0, 0) points along base +y after a +90 deg turn about z,
    # so the point (1, 0, 0) lands at (0.1, 0.2 + 1, 0.3).
    assert t @ np.array([1.0, 0, 0, 1]) == pytest.approx([0.1, 1.2, 0.3, 1.0])
    assert t[3].tolist() == [0, 0, 0, 1]
    assert c.matrix_to_frame(t).tolist() == pytest.approx(wire)
    # stacks convert too
    stack = c.frame_to_matrix(np.array([wire, wire]))
    assert stack.shape == (2, 4, 4) and np.array_equal(stack[1], t)


def test_wrench_order_hand_example() -> None:
    # Wire [Fx, Fy, Fz, Tz, Ty, Tx] = [1, 2, 3, 30, 20, 10] means tx=10, ty=20, tz=30.
    assert c.wrench_from_wire([1, 2, 3, 30, 20, 10]).tolist() == [1, 2, 3, 10, 20, 30]
    assert c.wrench_to_wire([1, 2, 3, 10, 20, 30]).tolist() == [1, 2, 3, 30, 20, 10]


def test_cart_gains_order_hand_example() -> None:
    # Ours [x, y, z, rx, ry, rz] = [1000, 1100, 1200, 10, 20, 30]; wire is
    # [x, y, z, A(Rz), B(Ry), C(Rx)] = [1000, 1100, 1200, 30, 20, 10].
    assert c.cart_gains_to_wire([1000, 1100, 1200, 10, 20, 30]).tolist() == [
        1000,
        1100,
        1200,
        30,
        20,
        10,
    ]
    assert c.cart_gains_from_wire([1000, 1100, 1200, 30, 20, 10]).tolist() == [
        1000,
        1100,
        1200,
        10,
        20,
        30,
    ]


def test_jacobian_rows_hand_example() -> None:
    # Wire J[i][j] = jacobian[i*7+j], rows X, Y, Z, RZ, RY, RX. Fill wire row i
    # with 10*i + j so every entry says where it came from.
    wire = [10 * i + j for i in range(6) for j in range(7)]
    jac = c.jacobian_from_wire(wire)
    assert jac.shape == (6, 7)
    assert jac[0].tolist() == [0, 1, 2, 3, 4, 5, 6]  # x  <- X  (wire row 0)
    assert jac[2, 6] == 26  # z <- Z (wire row 2)
    assert jac[3].tolist() == [50, 51, 52, 53, 54, 55, 56]  # rx <- RX (wire row 5)
    assert jac[4, 0] == 40  # ry <- RY (wire row 4)
    assert jac[5].tolist() == [30, 31, 32, 33, 34, 35, 36]  # rz <- RZ (wire row 3)
    assert c.jacobian_to_wire(jac).tolist() == wire


def test_mass_matrix_is_row_major() -> None:
    wire = list(range(49))  # M[i][j] = 7*i + j
    m = c.mass_matrix_from_wire(wire)
    assert m[0, 1] == 1 and m[1, 0] == 7 and m[6, 5] == 47
    assert c.mass_matrix_to_wire(m).tolist() == wire


def test_conversion_shape_errors() -> None:
    with pytest.raises(ValueError, match="12"):
        c.frame_to_matrix(np.zeros(11))
    with pytest.raises(ValueError, match="4x4"):
        c.matrix_to_frame(np.zeros((3, 4)))
    with pytest.raises(ValueError, match="6"):
        c.wrench_from_wire(np.zeros(7))
    with pytest.raises(ValueError, match="6x7"):
        c.jacobian_to_wire(np.zeros((7, 6)))
    with pytest.raises(ValueError, match="shape"):
        c.frame_to_matrix(np.zeros(12), out=np.zeros((3, 4)))


def test_measurement_arrays_use_our_conventions() -> None:
    """Build a packet with struct (fact-sheet format) and read it as arrays."""
    vals: list[float] = [0.0] * len(struct.unpack(MSR_FMT, bytes(916)))
    # tuple positions: 4 head, 16 real, 16 int, 2 bool/fill, then intf ...
    pos = {"head": 0, "real": 4, "int": 20, "bool": 36, "timestamp": 38, "state": 39}
    vals[0:4] = [7, 6, 916, 0x2006]
    vals[pos["real"]] = 2.5
    vals[pos["int"] + 15] = -3
    vals[pos["bool"]] = 0b101
    vals[pos["timestamp"]] = 12.25
    vals[pos["state"]] = 0xFFFF  # INVALID
    vals[pos["state"] + 1] = 3  # quality PERFECT
    # after timestamp,state,quality: 3 sample-time/safety floats, 4 stat floats, missCounter
    miss = pos["state"] + 2 + 3 + 4
    vals[miss] = 123456
    robot = miss + 1
    vals[robot : robot + 4] = [0x7F, 2, 0, 0]
    data = robot + 4 + 7  # after power/control/error/warning and temperature[7]
    vals[data : data + 7] = [0.1 * k for k in range(7)]  # msrJntPos
    frame = [0, -1, 0, 0.5, 1, 0, 0, 0.25, 0, 0, 1, 0.125]
    vals[data + 7 : data + 19] = frame  # msrCartPos
    ft = data + 7 + 12 + 7 + 7 + 12 + 12 + 7 + 7  # estExtTcpFT
    vals[ft : ft + 6] = [1, 2, 3, 30, 20, 10]
    jac = ft + 6
    vals[jac : jac + 42] = [10 * i + j for i in range(6) for j in range(7)]
    raw = struct.pack(
        MSR_FMT, *[v if k == "f" else int(v) for k, v in zip(codes(MSR_FMT), vals, strict=True)]
    )

    a = c.MsrArrays()
    assert c.decode_msr_into(raw, a) is c.DecodeStatus.OK
    assert (a.send_seq, a.refl_seq) == (7, 6)
    assert a.krl_real[0] == 2.5 and a.krl_int[15] == -3 and a.krl_bool == 0b101
    assert a.timestamp == 12.25
    assert a.state is c.FriState.INVALID and a.quality is c.FriQuality.PERFECT
    assert a.miss_counter == 123456 and a.power == 0x7F
    assert a.control is c.ControlMode.CART_IMPEDANCE
    assert a.msr_jnt_pos == pytest.approx([0.1 * k for k in range(7)], rel=1e-7)
    assert a.msr_cart_pos.tolist() == [
        [0, -1, 0, 0.5],
        [1, 0, 0, 0.25],
        [0, 0, 1, 0.125],
        [0, 0, 0, 1],
    ]
    assert a.est_ext_tcp_ft.tolist() == [1, 2, 3, 10, 20, 30]
    assert a.jacobian[3, 0] == 50 and a.jacobian[5, 0] == 30
    # identical to the single-field conversions applied to the decoded record
    rec = c.decode_msr(raw)
    assert np.array_equal(a.jacobian, c.jacobian_from_wire(rec["data"]["jacobian"]))
    assert np.array_equal(a.msr_cart_pos, c.frame_to_matrix(rec["data"]["msrCartPos"]))
    b = c.msr_arrays_from_record(rec)
    assert np.array_equal(b.floats, a.floats) and b.krl_bool == a.krl_bool


def test_command_encoding_hand_example() -> None:
    cmd = c.CmdArrays()
    cmd.send_seq, cmd.refl_seq = 65535, 41
    cmd.flags = c.CmdFlags.CARTPOS | c.CmdFlags.CARTSTIFF | c.CmdFlags.CARTDAMP | c.CmdFlags.TCPFT
    cmd.jnt_pos[:] = np.arange(7) * 0.5
    pose = np.eye(4)
    pose[:3, 3] = [0.5, -0.25, 0.75]
    cmd.cart_pos[:] = pose
    cmd.add_tcp_ft[:] = [1, 2, 3, 10, 20, 30]  # tx=10, ty=20, tz=30
    cmd.cart_stiffness[:] = [1000, 1100, 1200, 10, 20, 30]  # rx, ry, rz stiffness
    cmd.cart_damping[:] = [0.7, 0.7, 0.7, 0.1, 0.2, 0.3]
    cmd.krl_int[:] = np.arange(16) - 8
    cmd.krl_bool = 1
    raw = c.encode_cmd(cmd, c.new_cmd_buffer())
    v = struct.unpack(CMD_FMT, raw)
    assert v[0:4] == (65535, 41, 376, 0x1005)
    assert v[20:36] == tuple(range(-8, 8)) and v[36] == 1
    flags = v[38]
    assert flags == 0x0100 | 0x1000 | 0x2000 | 0x0400
    jnt = 39
    assert v[jnt : jnt + 7] == tuple(0.5 * k for k in range(7))
    cart = jnt + 7
    assert v[cart : cart + 12] == (1, 0, 0, 0.5, 0, 1, 0, -0.25, 0, 0, 1, 0.75)
    ft = cart + 12 + 7
    assert v[ft : ft + 6] == (1, 2, 3, 30, 20, 10)  # wire: Fx Fy Fz Tz Ty Tx
    stiff = ft + 6 + 7 + 7
    assert v[stiff : stiff + 6] == (1000, 1100, 1200, 30, 20, 10)  # x y z A(Rz) B(Ry) C(Rx)
    damp = stiff + 6
    assert v[damp : damp + 6] == pytest.approx((0.7, 0.7, 0.7, 0.3, 0.2, 0.1), rel=1e-6)
    # the emulator reads it back into the same conventions
    back = c.CmdArrays()
    assert c.decode_cmd_into(raw, back) is c.DecodeStatus.OK
    assert back.add_tcp_ft.tolist() == [1, 2, 3, 10, 20, 30]
    assert back.cart_stiffness.tolist() == [1000, 1100, 1200, 10, 20, 30]
    assert np.array_equal(back.cart_pos, pose) and back.flags == cmd.flags
    assert back.send_seq == 65535 and back.refl_seq == 41


# --------------------------------------------------------------------------- round trips

f32 = st.floats(width=32, allow_nan=False, allow_infinity=False)
u16 = st.integers(0, 0xFFFF)


def f32_array(n: int) -> st.SearchStrategy[np.ndarray]:
    return hnp.arrays(np.float32, n, elements=f32).map(lambda a: a.astype(np.float64))


def pose_strategy() -> st.SearchStrategy[np.ndarray]:
    def build(top: np.ndarray) -> np.ndarray:
        m = np.zeros((4, 4))
        m[:3] = top.reshape(3, 4)
        m[3, 3] = 1.0
        return m

    return f32_array(12).map(build)


@settings(max_examples=60, deadline=None)
@given(
    floats=st.fixed_dictionaries(
        {
            "krl_real": f32_array(16),
            "temperature": f32_array(7),
            "msr_jnt_pos": f32_array(7),
            "cmd_jnt_pos": f32_array(7),
            "cmd_jnt_pos_fri_offset": f32_array(7),
            "msr_jnt_trq": f32_array(7),
            "est_ext_jnt_trq": f32_array(7),
            "gravity": f32_array(7),
            "est_ext_tcp_ft": f32_array(6),
            "jacobian": f32_array(42).map(lambda a: a.reshape(6, 7)),
            "mass_matrix": f32_array(49).map(lambda a: a.reshape(7, 7)),
            "msr_cart_pos": pose_strategy(),
            "cmd_cart_pos": pose_strategy(),
            "cmd_cart_pos_fri_offset": pose_strategy(),
        }
    ),
    scalars=st.fixed_dictionaries(
        {
            k: f32
            for k in (
                "timestamp",
                "msr_sample_time",
                "cmd_sample_time",
                "safety_limits",
                "answer_rate",
                "latency",
                "jitter",
                "miss_rate",
            )
        }
    ),
    ints=st.fixed_dictionaries(
        {
            k: u16
            for k in (
                "send_seq",
                "refl_seq",
                "krl_bool",
                "krl_fill",
                "state_raw",
                "quality_raw",
                "power",
                "control_raw",
                "error",
                "warning",
            )
        }
    ),
    miss=st.integers(0, 2**32 - 1),
    krl_int=hnp.arrays(np.int32, 16),
)
def test_measurement_round_trip_all_fields(
    floats: dict[str, np.ndarray],
    scalars: dict[str, float],
    ints: dict[str, int],
    miss: int,
    krl_int: np.ndarray,
) -> None:
    a = c.MsrArrays()
    for k, v in floats.items():
        getattr(a, k)[...] = v
    for k, s in scalars.items():
        setattr(a, k, s)
    for k, i in ints.items():
        setattr(a, k, i)
    a.miss_counter = miss
    a.krl_int[:] = krl_int
    raw = c.encode_msr(a, c.new_msr_buffer())
    assert len(raw) == 916 and c.check_msr(raw) is c.DecodeStatus.OK
    b = c.MsrArrays()
    assert c.decode_msr_into(raw, b) is c.DecodeStatus.OK
    for k, v in floats.items():
        assert np.array_equal(getattr(b, k), v), k
    for k, s in scalars.items():
        assert getattr(b, k) == s, k
    for k, i in ints.items():
        assert getattr(b, k) == i, k
    assert b.miss_counter == miss and np.array_equal(b.krl_int, krl_int)
    # the wire holds the wire conventions
    rec = c.decode_msr(raw)
    assert np.array_equal(rec["data"]["estExtTcpFT"], c.wrench_to_wire(floats["est_ext_tcp_ft"]))
    assert np.array_equal(rec["data"]["jacobian"], c.jacobian_to_wire(floats["jacobian"]))
    assert np.array_equal(rec["data"]["cmdCartPos"], c.matrix_to_frame(floats["cmd_cart_pos"]))


@settings(max_examples=60, deadline=None)
@given(
    floats=st.fixed_dictionaries(
        {
            "krl_real": f32_array(16),
            "jnt_pos": f32_array(7),
            "cart_pos": pose_strategy(),
            "add_jnt_trq": f32_array(7),
            "add_tcp_ft": f32_array(6),
            "jnt_stiffness": f32_array(7),
            "jnt_damping": f32_array(7),
            "cart_stiffness": f32_array(6),
            "cart_damping": f32_array(6),
        }
    ),
    ints=st.fixed_dictionaries({k: u16 for k in ("send_seq", "refl_seq", "krl_bool", "krl_fill")}),
    flags=st.integers(0, 2**32 - 1),
    krl_int=hnp.arrays(np.int32, 16),
)
def test_command_round_trip_all_fields(
    floats: dict[str, np.ndarray], ints: dict[str, int], flags: int, krl_int: np.ndarray
) -> None:
    a = c.CmdArrays()
    for k, v in floats.items():
        getattr(a, k)[...] = v
    for k, i in ints.items():
        setattr(a, k, i)
    a.cmd_flags = flags
    a.krl_int[:] = krl_int
    raw = c.encode_cmd(a)
    assert len(raw) == 376 and c.check_cmd(raw) is c.DecodeStatus.OK
    b = c.CmdArrays()
    assert c.decode_cmd_into(raw, b) is c.DecodeStatus.OK
    for k, v in floats.items():
        assert np.array_equal(getattr(b, k), v), k
    for k, i in ints.items():
        assert getattr(b, k) == i, k
    assert b.cmd_flags == flags and np.array_equal(b.krl_int, krl_int)
    rec = c.decode_cmd(raw)
    assert np.array_equal(rec["cmd"]["addTcpFT"], c.wrench_to_wire(floats["add_tcp_ft"]))
    assert np.array_equal(
        rec["cmd"]["cartStiffness"], c.cart_gains_to_wire(floats["cart_stiffness"])
    )


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_random_packets_survive_decode_then_encode_byte_for_byte(seed: int) -> None:
    rng = np.random.default_rng(seed)
    msr = random_packet(rng, 916, 0x2006, MSR_FLOAT_WORDS)
    a = c.MsrArrays()
    assert c.decode_msr_into(msr, a) is c.DecodeStatus.OK
    assert c.encode_msr(a) == msr
    cmd = random_packet(rng, 376, 0x1005, CMD_FLOAT_WORDS)
    b = c.CmdArrays()
    assert c.decode_cmd_into(cmd, b) is c.DecodeStatus.OK
    assert c.encode_cmd(b) == cmd


# --------------------------------------------------------------------------- encoding errors


def test_encoding_refuses_non_finite_and_out_of_range_floats() -> None:
    cmd = c.CmdArrays()
    cmd.jnt_pos[3] = np.nan
    with pytest.raises(PacketEncodeError, match=r"cmd\.jntPos.*entry 3"):
        c.encode_cmd(cmd)
    cmd.jnt_pos[3] = 0.0
    cmd.cart_stiffness[4] = 1e39  # beyond float32
    with pytest.raises(PacketEncodeError, match=r"cmd\.cartStiffness"):
        c.encode_cmd(cmd)
    cmd.cart_stiffness[4] = -np.inf
    with pytest.raises(DriverError):
        c.encode_cmd(cmd)
    m = c.MsrArrays()
    m.gravity[0] = np.inf
    with pytest.raises(PacketEncodeError, match=r"data\.gravity"):
        c.encode_msr(m)


@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf, 1e39, -1e300, 1.7e308])
def test_encoding_rejects_bad_floats_without_numpy_warnings(value: float) -> None:
    cmd = c.CmdArrays()
    cmd.add_jnt_trq[6] = value
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(PacketEncodeError, match=r"cmd\.addJntTrq.*entry 6"):
            c.encode_cmd(cmd)


def test_encoding_accepts_the_float32_extremes_and_ignores_the_pose_bottom_row() -> None:
    cmd = c.CmdArrays()
    big = float(np.finfo(np.float32).max)
    # two entries at the limit: legal, though their sum of squares exceeds the limit squared
    cmd.jnt_stiffness[:2] = [big, -big]
    cmd.cart_pos[3] = [np.nan, 5, 6, 7]  # not on the wire
    raw = c.encode_cmd(cmd)
    back = c.CmdArrays()
    c.decode_cmd_into(raw, back)
    assert back.jnt_stiffness[:2].tolist() == [big, -big]
    assert back.cart_pos[3].tolist() == [0, 0, 0, 1]


def test_encoding_refuses_integers_that_do_not_fit() -> None:
    cmd = c.CmdArrays()
    cmd.send_seq = 65536
    with pytest.raises(PacketEncodeError, match="sendSeqCount"):
        c.encode_cmd(cmd)
    cmd.send_seq = 0
    cmd.cmd_flags = -1
    with pytest.raises(PacketEncodeError, match="cmdFlags"):
        c.encode_cmd(cmd)
    m = c.MsrArrays()
    m.state_raw = -1  # must go through enum_to_wire / the state property
    with pytest.raises(PacketEncodeError, match=r"intf\.state"):
        c.encode_msr(m)
    m.state_raw = 0
    m.krl_int = np.zeros(16, np.int64)  # type: ignore[assignment]
    with pytest.raises(PacketEncodeError, match=r"krl\.intData"):
        c.encode_msr(m)


def test_field_name_lists_cover_every_float_attribute() -> None:
    m, cmd = c.MsrArrays(), c.CmdArrays()
    assert len(c.MSR_ARRAY_FIELDS) == 14 and len(c.MSR_SCALAR_FIELDS) == 8
    sizes = [np.asarray(getattr(m, k)).size for k in c.MSR_ARRAY_FIELDS + c.MSR_SCALAR_FIELDS]
    # 175 data floats + 16 KRL + 7 temperature + 8 intf floats, with 3 x 4 pose bottom entries
    assert sum(sizes) == 175 + 16 + 7 + 8 + 3 * 4 == m.floats.size
    assert all(isinstance(getattr(m, k), float) for k in c.MSR_SCALAR_FIELDS)
    sizes = [getattr(cmd, k).size for k in c.CMD_ARRAY_FIELDS]
    assert sum(sizes) == 58 + 16 + 4 == cmd.floats.size


def test_packet_buffer_is_reused_and_returned_bytes_are_copies() -> None:
    pb = c.new_cmd_buffer()
    cmd = c.CmdArrays()
    cmd.jnt_pos[0] = 1.0
    first = c.encode_cmd(cmd, pb)
    cmd.jnt_pos[0] = 2.0
    second = c.encode_cmd(cmd, pb)
    assert struct.unpack_from("<f", first, 144) == (1.0,)
    assert struct.unpack_from("<f", second, 144) == (2.0,)
    assert pb.record["cmd"]["jntPos"][0] == 2.0 and pb.tobytes() == second
    with pytest.raises(ValueError, match="command PacketBuffer"):
        c.encode_cmd(cmd, c.new_msr_buffer())


def test_decoded_record_is_a_view_of_the_buffer() -> None:
    buf = bytearray(c.encode_msr(c.MsrArrays()))
    rec = c.decode_msr(buf)
    struct.pack_into("<f", buf, 216, 1.5)  # data.msrJntPos[0]
    assert rec["data"]["msrJntPos"][0] == 1.5
    assert not c.decode_msr(bytes(buf))["data"]["msrJntPos"].flags.writeable


# --------------------------------------------------------------------------- rejection


def valid_msr() -> bytes:
    return c.encode_msr(c.MsrArrays())


def valid_cmd() -> bytes:
    return c.encode_cmd(c.CmdArrays())


def with_header(raw: bytes, size: int, ident: int) -> bytes:
    b = bytearray(raw)
    struct.pack_into("<HH", b, 4, size, ident)
    return bytes(b)


@pytest.mark.parametrize(
    ("raw", "status", "reason"),
    [
        (b"", c.DecodeStatus.TOO_SHORT, "916"),
        (valid_msr()[:915], c.DecodeStatus.TOO_SHORT, "915 bytes"),
        (valid_msr() + b"\0", c.DecodeStatus.TOO_LONG, "917 bytes"),
        (valid_cmd(), c.DecodeStatus.TOO_SHORT, "376 bytes"),
        (with_header(valid_msr(), 916, 0x1005), c.DecodeStatus.WRONG_ID, "0x1005"),
        (with_header(valid_msr(), 376, 0x2006), c.DecodeStatus.WRONG_PACKET_SIZE, "376"),
    ],
)
def test_measurement_rejections(raw: bytes, status: c.DecodeStatus, reason: str) -> None:
    stats = c.DecodeStats()
    assert c.check_msr(raw) is status
    with pytest.raises(MalformedPacketError, match=reason) as info:
        c.decode_msr(raw, source=("192.168.0.20", 49938), stats=stats)
    assert str(info.value).startswith("192.168.0.20:49938: ")
    assert info.value.reason == status.name.lower()
    out = c.MsrArrays()
    out.msr_jnt_pos[:] = 9.0
    assert c.decode_msr_into(memoryview(raw), out, stats=stats) is status
    assert out.msr_jnt_pos.tolist() == [9.0] * 7  # untouched
    assert stats[status] == 2 and stats.rejected == 2 and stats.ok == 0


def test_command_rejections_and_stats() -> None:
    stats = c.DecodeStats()
    out = c.CmdArrays()
    cases = [
        valid_cmd(),
        valid_cmd()[:-1],
        valid_cmd() + b"xx",
        with_header(valid_cmd(), 376, 0x2006),
        with_header(valid_cmd(), 375, 0x1005),
        valid_msr(),
    ]
    got = [c.decode_cmd_into(r, out, stats=stats) for r in cases]
    assert got == [
        c.DecodeStatus.OK,
        c.DecodeStatus.TOO_SHORT,
        c.DecodeStatus.TOO_LONG,
        c.DecodeStatus.WRONG_ID,
        c.DecodeStatus.WRONG_PACKET_SIZE,
        c.DecodeStatus.TOO_LONG,
    ]
    assert stats.as_dict() == {
        "ok": 1,
        "too_short": 1,
        "too_long": 2,
        "wrong_id": 1,
        "wrong_packet_size": 1,
    }
    assert stats.total == 6
    stats.reset()
    assert stats.total == 0
    with pytest.raises(MalformedPacketError, match="<buffer>"):
        c.decode_cmd(cases[3])


@pytest.mark.filterwarnings("ignore:invalid value encountered in cast:RuntimeWarning")
@pytest.mark.parametrize(
    ("size", "ident", "size_bytes", "id_bytes", "which"),
    [
        (916, 0x2006, b"\x94\x03", b"\x06\x20", "msr"),
        (376, 0x1005, b"\x78\x01", b"\x05\x10", "cmd"),
    ],
)
def test_fuzz_every_datagram_is_accepted_or_counted_as_a_specific_rejection(
    size: int, ident: int, size_bytes: bytes, id_bytes: bytes, which: str
) -> None:
    """20,000 random, truncated, oversized, wrong-id and wrong-size datagrams per decoder."""
    if which == "msr":
        decode_into, decode, arrays = c.decode_msr_into, c.decode_msr, c.MsrArrays()
    else:
        decode_into, decode, arrays = c.decode_cmd_into, c.decode_cmd, c.CmdArrays()
    rng = np.random.default_rng(4242)
    kinds = ["random", "truncated", "oversized", "wrong_id", "wrong_size", "valid"]
    expected = {s: 0 for s in c.DecodeStatus}
    stats = c.DecodeStats()
    raised = 0
    base = bytearray(size)
    for i in range(20_000):
        kind = kinds[i % len(kinds)]
        body = rng.integers(0, 256, 1200, dtype=np.uint8).tobytes()
        if kind == "random":
            raw = body[: int(rng.integers(0, 1200))]
        else:
            base[:] = body[:size]
            wire_id = int(rng.integers(0, 65536)) if kind == "wrong_id" else ident
            if wire_id == ident and kind == "wrong_id":
                wire_id = 0x2006 + 0x1005 - ident  # the other packet's id
            wire_size = int(rng.integers(0, 65536)) if kind == "wrong_size" else size
            if wire_size == size and kind == "wrong_size":
                wire_size = size + 1
            struct.pack_into("<HH", base, 4, wire_size, wire_id)
            raw = bytes(base)
            if kind == "truncated":
                raw = raw[: int(rng.integers(0, size))]
            elif kind == "oversized":
                raw = raw + body[: int(rng.integers(1, 200))]
        # the test's own classification, independent of the codec
        n = len(raw)
        if n < size:
            want = c.DecodeStatus.TOO_SHORT
        elif n > size:
            want = c.DecodeStatus.TOO_LONG
        elif raw[6:8] != id_bytes:
            want = c.DecodeStatus.WRONG_ID
        elif raw[4:6] != size_bytes:
            want = c.DecodeStatus.WRONG_PACKET_SIZE
        else:
            want = c.DecodeStatus.OK
        expected[want] += 1
        assert decode_into(raw, arrays, stats=stats) is want  # type: ignore[arg-type]
        try:
            decode(raw)
        except MalformedPacketError as err:
            raised += 1
            assert err.reason == want.name.lower()
    assert stats.total == 20_000
    assert [stats[s] for s in c.DecodeStatus] == [expected[s] for s in c.DecodeStatus]
    assert raised == stats.rejected
    assert all(expected[s] > 100 for s in c.DecodeStatus)  # every branch was exercised
