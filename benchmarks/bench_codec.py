"""Throughput of the FRI and Net F/T codecs against plain ``struct`` on the same packets.

Run: ``python benchmarks/bench_codec.py [--repeat 7] [--seconds 0.2]``

Each row times one operation on identical input, as the median over
``--repeat`` runs of about ``--seconds`` each, and prints operations per
second and the ratio codec / struct (above 1: the codec is faster). The
``struct`` formats are the fact sheet's (shared/research/fri_netft.md).

Two kinds of struct baseline appear:
* "raw": ``struct.unpack``/``pack`` alone, i.e. a tuple in wire order with no
  validation and no conversion; a lower bound for any struct-based codec.
* "conv": struct plus the conversions the codec does (header check, arrays in
  our conventions: 4x4 poses, wrench and gain order, 6x7 Jacobian).
"""

from __future__ import annotations

import argparse
import statistics
import struct
import timeit
from collections.abc import Callable

import numpy as np

from drivers.fri import codec as fri
from drivers.netft import codec as netft

MSR_FMT = "<HHHH16f16iHHfHHfffffffIHHHH7f7f12f7f7f12f12f7f7f6f42f49f7f"
CMD_FMT = "<HHHH16f16iHHI7f12f7f6f7f7f6f6f"
RECORD_FMT = ">III6i"
REQUEST_FMT = ">HHI"
PERM = [0, 1, 2, 5, 4, 3]


def ops_per_second(fn: Callable[[], object], repeat: int, seconds: float) -> float:
    timer = timeit.Timer(fn)
    number, _ = timer.autorange()
    number = max(1, int(number * seconds / 0.2))
    runs = timer.repeat(repeat=repeat, number=number)
    return number / statistics.median(runs)


def sample_measurement() -> bytes:
    rng = np.random.default_rng(1)
    a = fri.MsrArrays()
    a.floats[:] = rng.normal(size=a.floats.size)
    for pose in (a.msr_cart_pos, a.cmd_cart_pos, a.cmd_cart_pos_fri_offset):
        pose[3] = [0, 0, 0, 1]
    a.krl_int[:] = rng.integers(-100, 100, 16)
    a.send_seq, a.state, a.quality = 1234, fri.FriState.CMD, fri.FriQuality.PERFECT
    return fri.encode_msr(a)


def sample_command() -> fri.CmdArrays:
    rng = np.random.default_rng(2)
    c = fri.CmdArrays()
    c.floats[:] = rng.normal(size=c.floats.size)
    c.cart_pos[3] = [0, 0, 0, 1]
    c.flags = fri.CmdFlags.CARTPOS | fri.CmdFlags.CARTSTIFF | fri.CmdFlags.CARTDAMP
    c.send_seq, c.refl_seq = 7, 1234
    return c


def struct_msr_to_arrays(s: struct.Struct, raw: bytes) -> dict[str, object]:
    """A straightforward struct-based decoder producing the same arrays."""
    if len(raw) != fri.MSR_SIZE:
        raise ValueError("size")
    v = s.unpack(raw)
    if v[3] != fri.MSR_DATAGRAM_ID or v[2] != fri.MSR_SIZE:
        raise ValueError("header")
    data = np.array(v[60:], dtype=np.float64)
    pose = np.empty((4, 4))
    pose[:3] = data[7:19].reshape(3, 4)
    pose[3] = [0, 0, 0, 1]
    return {
        "seq": v[0],
        "state": v[39],
        "timestamp": v[38],
        "q": data[0:7],
        "pose": pose,
        "tau": data[57:64],
        "tau_ext": data[64:71],
        "wrench": data[71:77][PERM],
        "jacobian": data[77:119].reshape(6, 7)[PERM],
        "mass": data[119:168].reshape(7, 7),
    }


def struct_encode_cmd(s: struct.Struct, c: fri.CmdArrays) -> bytes:
    """A straightforward struct-based encoder from arrays in our conventions."""
    return s.pack(
        c.send_seq,
        c.refl_seq,
        fri.CMD_SIZE,
        fri.CMD_DATAGRAM_ID,
        *c.krl_real.tolist(),
        *c.krl_int.tolist(),
        c.krl_bool,
        c.krl_fill,
        c.cmd_flags,
        *c.jnt_pos.tolist(),
        *c.cart_pos[:3].ravel().tolist(),
        *c.add_jnt_trq.tolist(),
        *c.add_tcp_ft[PERM].tolist(),
        *c.jnt_stiffness.tolist(),
        *c.jnt_damping.tolist(),
        *c.cart_stiffness[PERM].tolist(),
        *c.cart_damping[PERM].tolist(),
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--seconds", type=float, default=0.2)
    args = ap.parse_args()
    rep, sec = args.repeat, args.seconds

    msr_s, cmd_s = struct.Struct(MSR_FMT), struct.Struct(CMD_FMT)
    msr_raw = sample_measurement()
    cmd_arrays = sample_command()
    cmd_buf = fri.new_cmd_buffer()
    cmd_raw = fri.encode_cmd(cmd_arrays, cmd_buf)
    msr_arrays = fri.MsrArrays()
    fri.decode_msr_into(msr_raw, msr_arrays)
    msr_buf = fri.new_msr_buffer()
    cmd_back = fri.CmdArrays()
    msr_values = msr_s.unpack(msr_raw)
    cmd_values = cmd_s.unpack(cmd_raw)
    stats = fri.DecodeStats()
    # Both sides must do the same work: check they produce the same result.
    ref = struct_msr_to_arrays(msr_s, msr_raw)
    for key, mine in [
        ("q", msr_arrays.msr_jnt_pos),
        ("pose", msr_arrays.msr_cart_pos),
        ("tau", msr_arrays.msr_jnt_trq),
        ("tau_ext", msr_arrays.est_ext_jnt_trq),
        ("wrench", msr_arrays.est_ext_tcp_ft),
        ("jacobian", msr_arrays.jacobian),
        ("mass", msr_arrays.mass_matrix),
    ]:
        assert np.array_equal(ref[key], mine), key  # type: ignore[arg-type]
    assert struct_encode_cmd(cmd_s, cmd_arrays) == cmd_raw

    rng = np.random.default_rng(3)
    rdt1 = netft.encode_rdt(1, 1, 0, rng.integers(-(10**6), 10**6, (1, 6)))
    rdt40 = netft.encode_rdt(np.arange(40), np.arange(40), 0, rng.integers(-9, 9, (40, 6)))
    rdt_out = netft.RdtSamples.empty()
    rec40 = struct.Struct(">" + "III6i" * 40)
    rec1 = struct.Struct(RECORD_FMT)
    req = struct.Struct(REQUEST_FMT)

    rows: list[tuple[str, Callable[[], object], str, Callable[[], object]]] = [
        (
            "FRI msr decode -> record view",
            lambda: fri.decode_msr(msr_raw, stats=stats),
            "raw unpack",
            lambda: msr_s.unpack(msr_raw),
        ),
        (
            "FRI msr decode -> arrays (ours)",
            lambda: fri.decode_msr_into(msr_raw, msr_arrays, stats=stats),
            "raw unpack",
            lambda: msr_s.unpack(msr_raw),
        ),
        (
            "FRI msr decode -> arrays (ours)",
            lambda: fri.decode_msr_into(msr_raw, msr_arrays, stats=stats),
            "conv",
            lambda: struct_msr_to_arrays(msr_s, msr_raw),
        ),
        (
            "FRI cmd encode <- arrays (ours)",
            lambda: fri.encode_cmd(cmd_arrays, cmd_buf),
            "raw pack",
            lambda: cmd_s.pack(*cmd_values),
        ),
        (
            "FRI cmd encode <- arrays (ours)",
            lambda: fri.encode_cmd(cmd_arrays, cmd_buf),
            "conv",
            lambda: struct_encode_cmd(cmd_s, cmd_arrays),
        ),
        (
            "FRI cmd decode -> arrays (emulator)",
            lambda: fri.decode_cmd_into(cmd_raw, cmd_back),
            "raw unpack",
            lambda: cmd_s.unpack(cmd_raw),
        ),
        (
            "FRI msr encode <- arrays (emulator)",
            lambda: fri.encode_msr(msr_arrays, msr_buf),
            "raw pack",
            lambda: msr_s.pack(*msr_values),
        ),
        (
            "RDT decode 1 record",
            lambda: netft.decode_rdt_into(rdt1, rdt_out),
            "raw unpack",
            lambda: rec1.unpack(rdt1),
        ),
        (
            "RDT decode 40 records",
            lambda: netft.decode_rdt_into(rdt40, rdt_out),
            "raw unpack",
            lambda: rec40.unpack(rdt40),
        ),
        (
            "RDT request encode",
            lambda: netft.encode_request(netft.RdtCommand.START_REALTIME, 0),
            "raw pack",
            lambda: req.pack(0x1234, 2, 0),
        ),
    ]

    print(f"median of {rep} runs of ~{sec:.2f} s each; ratio = codec / struct ops per second")
    print(f"{'operation':38} {'codec op/s':>12} {'struct':>10} {'struct op/s':>12} {'ratio':>7}")
    for name, codec_fn, kind, struct_fn in rows:
        a = ops_per_second(codec_fn, rep, sec)
        b = ops_per_second(struct_fn, rep, sec)
        print(f"{name:38} {a:12,.0f} {kind:>10} {b:12,.0f} {a / b:7.2f}")


if __name__ == "__main__":
    main()
