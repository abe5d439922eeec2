"""The RTDE codec against byte offsets written out here (from the RTDE Guide's layouts),
and 100,000 fuzzed packages each way: no crash, every one counted."""

from __future__ import annotations

import struct
from collections import Counter

import numpy as np
import pytest

from drivers.errors import MalformedPacketError, PacketEncodeError
from drivers.ur.rtde import codec
from drivers.ur.rtde.codec import PackageType
from drivers.ur.rtde.fields import FIELD_TYPES, Recipe, field_size
from drivers.ur.rtde.variables import INPUTS, OUTPUTS

ALL_TYPES = ("BOOL", "UINT8", "UINT32", "UINT64", "INT32", "DOUBLE", "VECTOR3D", "VECTOR6D",
             "VECTOR6INT32", "VECTOR6UINT32")
ALL_NAMES = tuple(f"f_{t.lower()}" for t in ALL_TYPES)


def from_client(data: bytes, recipes: dict[int, Recipe] | None = None) -> codec.ClientMessage:
    size, ptype = struct.unpack_from(">HB", data)
    assert size == len(data)
    return codec.decode_from_client(ptype, data[3:], recipes or {}, "test")


def from_controller(data: bytes, recipes: dict[int, Recipe] | None = None
                    ) -> codec.ControllerMessage:
    size, ptype = struct.unpack_from(">HB", data)
    assert size == len(data)
    return codec.decode_from_controller(ptype, data[3:], recipes or {}, "test")


# ----------------------------------------------------------------------------- bytes


def test_package_type_codes_are_the_guides_letters() -> None:
    assert {t.name: chr(t) for t in PackageType} == {
        "REQUEST_PROTOCOL_VERSION": "V", "GET_URCONTROL_VERSION": "v", "TEXT_MESSAGE": "M",
        "DATA_PACKAGE": "U", "CONTROL_PACKAGE_SETUP_OUTPUTS": "O",
        "CONTROL_PACKAGE_SETUP_INPUTS": "I", "CONTROL_PACKAGE_START": "S",
        "CONTROL_PACKAGE_PAUSE": "P"}


def test_field_sizes_are_the_guides() -> None:
    assert {t: field_size(t) for t in FIELD_TYPES} == {
        "BOOL": 1, "UINT8": 1, "UINT32": 4, "UINT64": 8, "INT32": 4, "DOUBLE": 8,
        "VECTOR3D": 24, "VECTOR6D": 48, "VECTOR6INT32": 24, "VECTOR6UINT32": 24}


@pytest.mark.parametrize(("msg", "wire"), [
    (codec.RequestProtocolVersion(2), b"\x00\x05V\x00\x02"),
    (codec.GetControllerVersion(), b"\x00\x03v"),
    (codec.Start(), b"\x00\x03S"),
    (codec.Pause(), b"\x00\x03P"),
    (codec.SetupInputs(("input_int_register_0",)), b"\x00\x17I" + b"input_int_register_0"),
    (codec.SetupOutputs(500.0, ("timestamp", "actual_q")),
     b"\x00\x1dO" + b"\x40\x7f\x40\x00\x00\x00\x00\x00" + b"timestamp,actual_q"),
    (codec.SetupOutputs(125.0, ("timestamp",), trailing_comma=True),
     b"\x00\x15O" + b"\x40\x5f\x40\x00\x00\x00\x00\x00" + b"timestamp,"),
    (codec.TextMessage("hi", "src", codec.MessageLevel.INFO), b"\x00\x0bM\x02hi\x03src\x03"),
])
def test_client_packages_at_their_byte_offsets(msg: codec.ClientMessage, wire: bytes) -> None:
    assert codec.encode(msg) == wire
    assert from_client(wire) == msg


@pytest.mark.parametrize(("msg", "wire"), [
    (codec.Accepted(PackageType.REQUEST_PROTOCOL_VERSION, True), b"\x00\x04V\x01"),
    (codec.Accepted(PackageType.REQUEST_PROTOCOL_VERSION, False), b"\x00\x04V\x00"),
    (codec.Accepted(PackageType.CONTROL_PACKAGE_START, True), b"\x00\x04S\x01"),
    (codec.Accepted(PackageType.CONTROL_PACKAGE_PAUSE, True), b"\x00\x04P\x01"),
    (codec.ControllerVersion(5, 15, 2, 1234),
     b"\x00\x13v" + b"\x00\x00\x00\x05\x00\x00\x00\x0f\x00\x00\x00\x02\x00\x00\x04\xd2"),
    (codec.RecipeReply(PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS, 1, ("DOUBLE", "VECTOR6D")),
     b"\x00\x13O\x01DOUBLE,VECTOR6D"),
    (codec.RecipeReply(PackageType.CONTROL_PACKAGE_SETUP_INPUTS, 0, ("IN_USE", "NOT_FOUND")),
     b"\x00\x14I\x00IN_USE,NOT_FOUND"),
    (codec.TextMessage("stop", "RTDE", codec.MessageLevel.ERROR), b"\x00\x0eM\x04stop\x04RTDE\x01"),
])
def test_controller_packages_at_their_byte_offsets(msg: codec.ControllerMessage,
                                                   wire: bytes) -> None:
    assert codec.encode(msg) == wire
    assert from_controller(wire) == msg


def every_type_recipe(recipe_id: int = 7) -> Recipe:
    return Recipe(recipe_id, ALL_NAMES, ALL_TYPES)


def every_type_values() -> dict[str, object]:
    return {
        "f_bool": True, "f_uint8": 0xAB, "f_uint32": 0xDEADBEEF, "f_uint64": 0x0102030405060708,
        "f_int32": -2, "f_double": 1.5, "f_vector3d": [1.0, -2.0, 0.25],
        "f_vector6d": [0.0, 1.0, 2.0, 3.0, 4.0, -0.5],
        "f_vector6int32": [-1, 0, 1, 2, 3, 2**31 - 1],
        "f_vector6uint32": [0, 1, 2, 3, 4, 2**32 - 1]}


def test_data_package_has_every_field_type_at_its_offset() -> None:
    recipe = every_type_recipe()
    wire = codec.package(PackageType.DATA_PACKAGE, b"\x07" + recipe.encode(every_type_values()))
    assert len(wire) == 150 and wire[:4] == b"\x00\x96U\x07"
    assert wire[4] == 1                                          # BOOL
    assert wire[5] == 0xAB                                       # UINT8
    assert wire[6:10] == b"\xde\xad\xbe\xef"                     # UINT32
    assert wire[10:18] == bytes(range(1, 9))                     # UINT64
    assert wire[18:22] == b"\xff\xff\xff\xfe"                    # INT32
    assert wire[22:30] == b"\x3f\xf8" + bytes(6)                 # DOUBLE 1.5
    assert wire[30:54] == struct.pack(">3d", 1.0, -2.0, 0.25)    # VECTOR3D
    assert wire[54:62] == bytes(8) and wire[94:102] == struct.pack(">d", -0.5)  # VECTOR6D
    assert wire[102:106] == b"\xff" * 4 and wire[122:126] == b"\x7f\xff\xff\xff"  # VECTOR6INT32
    assert wire[126:130] == bytes(4) and wire[146:150] == b"\xff" * 4  # VECTOR6UINT32
    msg = from_controller(wire, {7: recipe})
    assert isinstance(msg, codec.DataPackage) and msg.recipe_id == 7
    for name, value in every_type_values().items():
        np.testing.assert_array_equal(msg.record[name], value)
    assert codec.encode(msg) == wire


def test_data_package_of_the_wrong_length_or_recipe_is_refused() -> None:
    recipe = every_type_recipe()
    payload = b"\x07" + recipe.encode(every_type_values())
    for cut, reason in ((payload[:-1], "truncated"), (payload + b"\x00", "oversized"),
                        (b"", "truncated"), (b"\x08" + payload[1:], "unknown_recipe")):
        with pytest.raises(MalformedPacketError) as err:
            codec.decode_from_client(PackageType.DATA_PACKAGE, cut, {7: recipe}, ("10.0.0.2", 5))
        assert err.value.reason == reason and str(err.value).startswith("10.0.0.2:5: ")
    bad_bool = bytearray(payload)
    bad_bool[1] = 2
    with pytest.raises(MalformedPacketError, match="BOOL f_bool"):
        recipe.decode(bytes(bad_bool[1:]))


def test_encoding_refuses_what_a_field_cannot_carry() -> None:
    recipe = every_type_recipe()
    good = every_type_values()
    for name, bad in (("f_uint8", 256), ("f_int32", 2**31), ("f_uint32", -1),
                      ("f_double", float("nan")), ("f_vector6d", [0.0] * 5),
                      ("f_bool", 2), ("f_vector3d", ["a", "b", "c"])):
        with pytest.raises(PacketEncodeError, match=name):
            recipe.encode({**good, name: bad})
    with pytest.raises(PacketEncodeError, match="f_bool: no value"):
        recipe.encode({k: v for k, v in good.items() if k != "f_bool"})
    assert recipe.encode_outputs({**good, "f_double": float("inf")})[18:26] == struct.pack(
        ">d", float("inf"))
    with pytest.raises(PacketEncodeError, match="uint16"):
        codec.package(PackageType.TEXT_MESSAGE, bytes(65533))
    with pytest.raises(PacketEncodeError, match="bad variable name"):
        codec.encode(codec.SetupInputs(("a,b",)))


def test_a_record_with_a_non_finite_double_anywhere_is_refused_naming_its_field() -> None:
    recipe = every_type_recipe()
    record = recipe.empty()
    for name in recipe.names:
        record[name] = every_type_values()[name]
    assert recipe.encode(record) == recipe.encode(every_type_values())
    doubles = [(n, k) for n, t in zip(recipe.names, recipe.types, strict=True)
               for k in range({"DOUBLE": 1, "VECTOR3D": 3, "VECTOR6D": 6}.get(t, 0))]
    assert len(doubles) == 10
    for (name, k), bad in zip(doubles, [float("nan"), float("inf"), -float("inf")] * 4,
                              strict=False):
        broken = record.copy()
        if broken[name].ndim:
            broken[name][k] = bad
        else:
            broken[name] = bad
        with pytest.raises(PacketEncodeError, match=f"^cannot encode {name}: NaN or infinite"):
            recipe.encode(broken)
        assert recipe.encode_outputs(broken) == broken.tobytes()  # a controller's may


def test_ur_rtdes_trailing_comma_is_one_empty_name_dropped() -> None:
    assert codec.split_names("a,b,") == (("a", "b"), True)
    assert codec.split_names("a,,b") == (("a", "", "b"), False)
    assert codec.split_names("") == ((), False)


@pytest.mark.parametrize(("ptype", "payload", "reason"), [
    (PackageType.REQUEST_PROTOCOL_VERSION, b"\x00", "truncated"),
    (PackageType.REQUEST_PROTOCOL_VERSION, b"\x00\x02\x00", "oversized"),
    (PackageType.CONTROL_PACKAGE_START, b"\x00", "oversized"),
    (PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS, b"\x40\x7f", "truncated"),
    (PackageType.CONTROL_PACKAGE_SETUP_INPUTS, b"\xff\xfe", "bad_value"),
    (PackageType.TEXT_MESSAGE, b"\x05ab", "truncated"),
    (PackageType.TEXT_MESSAGE, b"\x01a\x01b\x03\x00", "oversized"),
    (ord("X"), b"", "unknown_type"),
])
def test_malformed_client_packages_name_the_reason(ptype: int, payload: bytes,
                                                   reason: str) -> None:
    with pytest.raises(MalformedPacketError) as err:
        codec.decode_from_client(ptype, payload, {}, "127.0.0.1:40000")
    assert err.value.reason == reason


@pytest.mark.parametrize(("ptype", "payload", "reason"), [
    (PackageType.REQUEST_PROTOCOL_VERSION, b"", "truncated"),
    (PackageType.REQUEST_PROTOCOL_VERSION, b"\x02", "bad_value"),
    (PackageType.GET_URCONTROL_VERSION, bytes(15), "truncated"),
    (PackageType.GET_URCONTROL_VERSION, bytes(17), "oversized"),
    (PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS, b"", "truncated"),
    (ord("V") + 1, b"", "unknown_type"),
])
def test_malformed_controller_packages_name_the_reason(ptype: int, payload: bytes,
                                                       reason: str) -> None:
    with pytest.raises(MalformedPacketError) as err:
        codec.decode_from_controller(ptype, payload, {}, "127.0.0.1:30004")
    assert err.value.reason == reason


def test_framer_cuts_a_stream_at_any_split() -> None:
    wires = [codec.encode(codec.RequestProtocolVersion(2)), codec.encode(codec.Start()),
             codec.encode(codec.TextMessage("x", "y", 2))]
    stream = b"".join(wires)
    for split in range(len(stream) + 1):
        framer = codec.Framer("t")
        got = []
        for part in (stream[:split], stream[split:]):
            framer.feed(part)
            while (p := framer.next()) is not None:
                got.append(codec.package(*p))
        assert got == wires and framer.pending == 0
    framer = codec.Framer("10.1.1.1:30004")
    framer.feed(b"\x00\x02V")
    with pytest.raises(MalformedPacketError, match=r"10\.1\.1\.1:30004: .*bad_size"):
        framer.next()
    framer = codec.Framer()
    framer.feed(b"\x00\x09U\x01")
    assert framer.next() is None and framer.pending == 4 and framer.pending_need() == 9


def test_catalogue_types_are_field_types_and_registers_are_there() -> None:
    assert set(OUTPUTS.values()) <= set(FIELD_TYPES) and set(INPUTS.values()) <= set(FIELD_TYPES)
    for name, t in (("timestamp", "DOUBLE"), ("actual_q", "VECTOR6D"),
                    ("actual_TCP_force", "VECTOR6D"), ("robot_mode", "INT32"),
                    ("safety_status_bits", "UINT32"), ("runtime_state", "UINT32"),
                    ("ft_raw_wrench", "VECTOR6D"), ("output_int_register_47", "INT32"),
                    ("input_double_register_24", "DOUBLE")):
        assert OUTPUTS[name] == t
    assert INPUTS["input_bit_register_64"] == "BOOL" and "input_bit_register_63" not in INPUTS
    assert INPUTS["input_int_register_0"] == "INT32" and "input_int_register_48" not in INPUTS
    assert "actual_q" not in INPUTS


# ----------------------------------------------------------------------------- fuzzing

TOTAL = 100_000


def seeds_from_client(recipe: Recipe) -> list[bytes]:
    return [codec.encode(m) for m in (
        codec.RequestProtocolVersion(2), codec.GetControllerVersion(), codec.Start(),
        codec.Pause(), codec.SetupOutputs(500.0, ("timestamp", "actual_q", "actual_TCP_force")),
        codec.SetupInputs(("input_double_register_0", "input_int_register_1")),
        codec.TextMessage("hello", "ffexp", 3))] + [
        codec.package(PackageType.DATA_PACKAGE, bytes((recipe.recipe_id,))
                      + recipe.encode(every_type_values()))]


def seeds_from_controller(recipe: Recipe) -> list[bytes]:
    return [codec.encode(m) for m in (
        codec.Accepted(PackageType.REQUEST_PROTOCOL_VERSION, True),
        codec.Accepted(PackageType.CONTROL_PACKAGE_START, True),
        codec.ControllerVersion(5, 15, 0, 1),
        codec.RecipeReply(PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS, 1, ("DOUBLE", "VECTOR6D")),
        codec.RecipeReply(PackageType.CONTROL_PACKAGE_SETUP_INPUTS, 0, ("IN_USE",)),
        codec.TextMessage("protective stop", "RTDE", 1))] + [
        codec.package(PackageType.DATA_PACKAGE, bytes((recipe.recipe_id,))
                      + recipe.encode(every_type_values()))]


def mutate(rng: np.random.Generator, seeds: list[bytes], noise: bytes, i: int) -> bytes:
    """One hostile buffer: a seed package bent one of seven ways (or pure noise)."""
    base = bytearray(seeds[(i // 8) % len(seeds)])
    kind = i % 8
    r = int(rng.integers(0, 1 << 30))
    chunk = noise[r % 4000:r % 4000 + 1 + r % 96]
    if kind == 0:                                   # random bytes flipped
        for k in range(1 + r % 4):
            base[(r >> (k * 5)) % len(base)] ^= 1 + (r >> 3) % 255
    elif kind == 1:                                 # truncated (the size field kept)
        base = base[:r % len(base)]
    elif kind == 2:                                 # grown (size field updated or not)
        base += chunk
        if r & 1:
            struct.pack_into(">H", base, 0, min(len(base), 0xFFFF))
    elif kind == 3:                                 # size field lies
        struct.pack_into(">H", base, 0, r % 300)
    elif kind == 4:                                 # another type letter
        base[2] = r % 256
    elif kind == 5:                                 # payload replaced, size kept honest
        base = bytearray(struct.pack(">HB", 3 + len(chunk), base[2])) + chunk
    elif kind == 6:                                 # pure noise
        base = bytearray(chunk)
    # kind 7: the seed itself
    return bytes(base)


def fuzz(direction: str) -> Counter[str]:
    rng = np.random.default_rng(25 if direction == "client" else 52)
    noise = rng.integers(0, 256, 4200, dtype=np.uint8).tobytes()
    recipe = every_type_recipe(recipe_id=1 if direction == "controller" else 2)
    recipes = {recipe.recipe_id: recipe}
    if direction == "client":
        seeds, decode = seeds_from_client(recipe), codec.decode_from_client
    else:
        seeds, decode = seeds_from_controller(recipe), codec.decode_from_controller
    counts: Counter[str] = Counter()
    for i in range(TOTAL):
        buf = mutate(rng, seeds, noise, i)
        framer = codec.Framer("fuzz")
        framer.feed(buf)
        try:
            got = framer.next()
            if got is None or framer.pending:
                counts["rejected:incomplete"] += 1
                continue
            msg = decode(got[0], got[1], recipes, "fuzz")
        except MalformedPacketError as exc:
            counts[f"rejected:{exc.reason}"] += 1
            continue
        counts["accepted"] += 1
        if isinstance(msg, codec.DataPackage):   # an accepted data package is its bytes
            assert msg.record.tobytes() == got[1][1:]
    return counts


@pytest.mark.parametrize("direction", ["client", "controller"])
def test_fuzzed_packages_never_crash_and_each_is_counted(direction: str) -> None:
    counts = fuzz(direction)
    assert sum(counts.values()) == TOTAL
    assert counts["accepted"] >= TOTAL // 8          # at least the untouched seeds
    rejected = {k for k in counts if k.startswith("rejected:")}
    assert {"rejected:incomplete", "rejected:bad_size", "rejected:truncated",
            "rejected:oversized", "rejected:unknown_type"} <= rejected
