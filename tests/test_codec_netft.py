"""Tests of the ATI Net F/T RDT codec (drivers.netft.codec).

Offsets, sizes, the command codes and the status bits come from the fact sheet
(shared/research/fri_netft.md, section 3); scaling examples are worked by hand.
"""

from __future__ import annotations

import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from drivers.errors import MalformedPacketError, PacketEncodeError
from drivers.netft import codec as n

REQUEST_FMT = ">HHI"  # uint16 0x1234, uint16 command, uint32 sample_count
RECORD_FMT = ">III6i"  # rdt_sequence, ft_sequence, status, Fx, Fy, Fz, Tx, Ty, Tz


# --------------------------------------------------------------------------- layout


def test_request_layout_matches_fact_sheet() -> None:
    d = n.REQUEST_DTYPE
    assert d.itemsize == 8 == struct.calcsize(REQUEST_FMT)
    expected = [("header", 0, ">u2"), ("command", 2, ">u2"), ("sample_count", 4, ">u4")]
    assert [(k, d.fields[k][1], d.fields[k][0]) for k in d.names] == [
        (k, off, np.dtype(t)) for k, off, t in expected
    ]


def test_record_layout_matches_fact_sheet() -> None:
    d = n.RECORD_DTYPE
    assert d.itemsize == 36 == struct.calcsize(RECORD_FMT)
    expected = [
        ("rdt_sequence", 0, ">u4"),
        ("ft_sequence", 4, ">u4"),
        ("status", 8, ">u4"),
        ("Fx", 12, ">i4"),
        ("Fy", 16, ">i4"),
        ("Fz", 20, ">i4"),
        ("Tx", 24, ">i4"),
        ("Ty", 28, ">i4"),
        ("Tz", 32, ">i4"),
    ]
    assert [(k, d.fields[k][1], d.fields[k][0]) for k in d.names] == [
        (k, off, np.dtype(t)) for k, off, t in expected
    ]


def test_command_codes() -> None:
    assert {m.name: m.value for m in n.RdtCommand} == {
        "STOP": 0,
        "START_REALTIME": 2,
        "START_BUFFERED": 3,
        "MULTI_UNIT": 4,
        "RESET_LATCH": 0x41,
        "SET_BIAS": 0x42,
    }


# --------------------------------------------------------------------------- requests


def test_request_bytes_hand_example() -> None:
    # 0x1234 big-endian is 12 34; command 2 is 00 02; count 0 is four zero bytes.
    assert n.encode_request(n.RdtCommand.START_REALTIME) == bytes.fromhex("1234000200000000")
    # All four count bytes are written (the bug noted in the fact sheet wrote the
    # low 16 bits twice).
    assert n.encode_request(n.RdtCommand.START_BUFFERED, 0x01020304) == bytes.fromhex(
        "1234000301020304"
    )
    assert n.encode_request(n.RdtCommand.SET_BIAS) == bytes.fromhex("1234004200000000")


@given(command=st.sampled_from(n.RdtCommand), count=st.integers(0, 2**32 - 1))
def test_request_round_trip(command: n.RdtCommand, count: int) -> None:
    raw = n.encode_request(command, count)
    assert struct.unpack(REQUEST_FMT, raw) == (0x1234, command, count)
    got = n.decode_request(raw)
    assert got == (command, count) and got.command is command


@pytest.mark.parametrize(
    ("raw", "reason"),
    [
        (b"", "wrong_size"),
        (bytes.fromhex("12340002000000"), "wrong_size"),
        (bytes.fromhex("123400020000000000"), "wrong_size"),
        (bytes.fromhex("4321000200000000"), "wrong_header"),
        (bytes.fromhex("1234000100000000"), "unknown_command"),  # loop-driven mode: not ours
    ],
)
def test_request_rejections(raw: bytes, reason: str) -> None:
    with pytest.raises(MalformedPacketError) as info:
        n.decode_request(raw, source=("10.0.0.5", 40000))
    assert info.value.reason == reason
    assert str(info.value).startswith("10.0.0.5:40000: ")


def test_request_encode_errors() -> None:
    with pytest.raises(PacketEncodeError, match="sample_count"):
        n.encode_request(n.RdtCommand.START_REALTIME, 2**32)
    with pytest.raises(ValueError):
        n.encode_request(7)  # type: ignore[arg-type]


# --------------------------------------------------------------------------- records


def test_records_agree_with_struct_on_random_datagrams() -> None:
    rng = np.random.default_rng(36)
    for k in (1, 2, 17, 40):
        raw = rng.integers(0, 256, 36 * k, dtype=np.uint8).tobytes()
        s = n.decode_rdt(raw)
        assert s.n == k
        for i in range(k):
            v = struct.unpack_from(RECORD_FMT, raw, 36 * i)
            assert (int(s.rdt_seq[i]), int(s.ft_seq[i]), int(s.status[i])) == v[:3]
            assert s.counts[i].tolist() == list(v[3:])
        assert s.counts.dtype == np.int32 and s.rdt_seq.dtype == np.uint32
        rec = np.frombuffer(raw, n.RECORD_DTYPE)
        assert rec["Tz"].tolist() == s.counts[:, 5].tolist()


@settings(max_examples=80, deadline=None)
@given(
    k=st.integers(1, 40),
    data=st.data(),
)
def test_records_round_trip(k: int, data: st.DataObject) -> None:
    rdt = data.draw(hnp.arrays(np.uint32, k))
    ft = data.draw(hnp.arrays(np.uint32, k))
    status = data.draw(hnp.arrays(np.uint32, k))
    counts = data.draw(hnp.arrays(np.int32, (k, 6)))
    raw = n.encode_rdt(rdt, ft, status, counts)
    assert len(raw) == 36 * k
    for i in range(k):
        v = struct.unpack_from(RECORD_FMT, raw, 36 * i)
        assert v == (int(rdt[i]), int(ft[i]), int(status[i]), *map(int, counts[i]))
    out = n.RdtSamples.empty()
    assert n.decode_rdt_into(raw, out) is n.RdtDecodeStatus.OK
    got = out.valid()
    assert got.n == k
    assert np.array_equal(got.rdt_seq, rdt) and np.array_equal(got.ft_seq, ft)
    assert np.array_equal(got.status, status) and np.array_equal(got.counts, counts)


def test_encode_wraps_sequences_and_broadcasts_scalars() -> None:
    raw = n.encode_rdt([2**32 - 1, 2**32], 5, 0, np.zeros((2, 6), np.int32))
    s = n.decode_rdt(raw)
    assert s.rdt_seq.tolist() == [2**32 - 1, 0] and s.ft_seq.tolist() == [5, 5]
    assert n.rdt_seq_delta(0, 2**32 - 1) == 1
    assert n.rdt_seq_delta(2**32 - 1, 0) == -1
    assert n.rdt_seq_delta(10, 7) == 3


def test_encode_errors() -> None:
    with pytest.raises(PacketEncodeError, match="records"):
        n.encode_rdt(0, 0, 0, np.zeros((41, 6), np.int32))
    with pytest.raises(PacketEncodeError, match="int32"):
        n.encode_rdt(0, 0, 0, np.array([2**31, 0, 0, 0, 0, 0], np.int64))
    with pytest.raises(PacketEncodeError, match="integer"):
        n.encode_rdt(0, 0, 0, np.zeros(6))
    with pytest.raises(PacketEncodeError, match="status"):
        n.encode_rdt(0, 0, -1, np.zeros(6, np.int32))
    with pytest.raises(ValueError, match="counts"):
        n.encode_rdt(0, 0, 0, np.zeros((2, 5), np.int32))


@pytest.mark.parametrize(
    ("length", "status"),
    [
        (0, n.RdtDecodeStatus.EMPTY),
        (35, n.RdtDecodeStatus.NOT_MULTIPLE),
        (37, n.RdtDecodeStatus.NOT_MULTIPLE),
        (73, n.RdtDecodeStatus.NOT_MULTIPLE),
        (36 * 41, n.RdtDecodeStatus.TOO_MANY),
        (36, n.RdtDecodeStatus.OK),
        (36 * 40, n.RdtDecodeStatus.OK),
    ],
)
def test_datagram_lengths(length: int, status: n.RdtDecodeStatus) -> None:
    raw = bytes(length)
    stats = n.RdtDecodeStats()
    assert n.check_rdt(raw)[0] is status
    out = n.RdtSamples.empty()
    out.n = 3
    assert n.decode_rdt_into(memoryview(raw), out, stats=stats) is status
    if status is n.RdtDecodeStatus.OK:
        assert out.n == length // 36 and stats.records == length // 36
        assert n.decode_rdt(raw).n == length // 36
    else:
        assert out.n == 0 and stats.records == 0
        with pytest.raises(MalformedPacketError, match=f"{length} bytes") as info:
            n.decode_rdt(raw, source="sensor", stats=stats)
        assert info.value.reason == status.name.lower()
        assert stats[status] == 2 and stats.rejected == 2
    assert stats.total == (1 if status is n.RdtDecodeStatus.OK else 2)


def test_decode_into_a_too_small_buffer_is_a_programming_error() -> None:
    with pytest.raises(ValueError, match="holds 2"):
        n.decode_rdt_into(bytes(36 * 3), n.RdtSamples.empty(2))


def test_fuzz_every_datagram_is_accepted_or_counted() -> None:
    rng = np.random.default_rng(7)
    stats = n.RdtDecodeStats()
    out = n.RdtSamples.empty()
    expected = {s: 0 for s in n.RdtDecodeStatus}
    records = 0
    for i in range(20_000):
        if i % 3 == 0:
            length = 36 * int(rng.integers(0, 45))  # whole records, some too many, some 0
        else:
            length = int(rng.integers(0, 1600))
        raw = rng.integers(0, 256, length, dtype=np.uint8).tobytes()
        if length == 0:
            want = n.RdtDecodeStatus.EMPTY
        elif length % 36:
            want = n.RdtDecodeStatus.NOT_MULTIPLE
        elif length > 36 * 40:
            want = n.RdtDecodeStatus.TOO_MANY
        else:
            want = n.RdtDecodeStatus.OK
            records += length // 36
        expected[want] += 1
        assert n.decode_rdt_into(raw, out, stats=stats) is want
        if want is n.RdtDecodeStatus.OK:
            first = struct.unpack_from(RECORD_FMT, raw)
            assert out.counts[0].tolist() == list(first[3:])
    assert stats.total == 20_000 and stats.records == records
    assert [stats[s] for s in n.RdtDecodeStatus] == [expected[s] for s in n.RdtDecodeStatus]
    assert all(v > 50 for v in expected.values())


# --------------------------------------------------------------------------- scaling


def test_counts_to_si_hand_example_n_and_nmm() -> None:
    # A box in N and N·mm with 1e6 counts per unit: 2.5e6 force counts are 2.5 N;
    # 3e6 torque counts are 3 N·mm = 0.003 N·m.
    cal = n.Calibration(1e6, 1e6, force_unit=1.0, torque_unit=0.001)
    w = n.counts_to_si([2_500_000, -1_000_000, 0, 3_000_000, 0, -500_000], cal)
    assert w == pytest.approx([2.5, -1.0, 0.0, 0.003, 0.0, -0.0005])
    assert n.Calibration.from_unit_codes(1e6, 1e6, 2, 4) == cal


def test_counts_to_si_other_units() -> None:
    # lbf and lbf·in: 1 lbf = 4.4482216152605 N; 1 lbf·in = 4.4482216152605 * 0.0254 N·m.
    cal = n.Calibration.from_unit_codes(1000.0, 2000.0, 1, 1)
    w = n.counts_to_si(np.array([[1000, 0, 0, 2000, 0, 0]]), cal)
    assert w[0, 0] == pytest.approx(4.4482216152605)
    assert w[0, 3] == pytest.approx(0.112984829027617)
    with pytest.raises(ValueError, match="unit code 9"):
        n.Calibration.from_unit_codes(1.0, 1.0, 9, 3)
    with pytest.raises(ValueError, match="counts_per_force"):
        n.Calibration(0.0, 1.0)


def test_si_to_counts_rounds_half_to_even_and_saturates() -> None:
    cal = n.Calibration(1.0, 1.0)  # one count per N and per N·m
    c = n.si_to_counts([0.5, 1.5, -2.5, 1e12, -np.inf, 2.4], cal)
    assert c.tolist() == [0, 2, -2, 2**31 - 1, -(2**31), 2]
    assert c.dtype == np.int32
    with pytest.raises(PacketEncodeError, match="NaN"):
        n.si_to_counts([np.nan, 0, 0, 0, 0, 0], cal)


@given(counts=hnp.arrays(np.int32, (3, 6)))
def test_counts_survive_si_and_back(counts: np.ndarray) -> None:
    cal = n.Calibration(1_000_000.0, 1_000_000.0, 1.0, 0.001)
    assert np.array_equal(n.si_to_counts(n.counts_to_si(counts, cal), cal), counts)


def test_counts_to_si_into_preallocated_output() -> None:
    cal = n.Calibration(10.0, 100.0)
    out = np.empty((2, 6))
    res = n.counts_to_si(np.array([[10, 20, 30, 100, 200, 300]] * 2, np.int32), cal, out=out)
    assert res is out and out[1].tolist() == [1, 2, 3, 1, 2, 3]


# --------------------------------------------------------------------------- status


def test_status_bits_from_fact_sheet() -> None:
    assert n.StatusBit.ERROR_SUMMARY == 0x80000000
    assert n.StatusBit.SATURATION_AD == 0x00020000
    assert n.StatusBit.MONITOR_LATCHED == 0x00010000
    assert n.describe_status(0) == []
    assert n.describe_status(0x80000000) == ["error summary"]
    assert n.describe_status(0x80020000) == ["error summary", "saturation or A/D error"]
    assert n.describe_status(0x00010000) == ["monitor condition latched"]
    assert n.describe_status(0x00400002) == ["network failure", "diagnostic bit 0x0002"]
    assert len(n.describe_status(0xFFFFFFFF)) == 32


def test_status_error_rule() -> None:
    assert not n.status_is_error(0)
    assert not n.status_is_error(0x80010000)  # latched threshold monitor: a warning
    assert n.status_is_error(0x80020000)  # saturation
    assert n.status_is_error(0x00010000)
