"""100,000 hostile datagrams at the remote driver and at the emulator: no crash, all counted.

Random bytes, truncated, oversized, wrong datagramId, wrong packetSize,
valid headers with random payloads (NaN, huge values, random sequence
numbers) and well-formed packets from a foreign address. The flood goes in
batches of 100; after each, one well-formed packet whose answer proves that
everything before it has been processed (UDP on loopback keeps the order of
one sender), so that nothing is lost to a full socket buffer and the counts
can be compared exactly. No sleeping: every wait is a socket read with a
timeout.
"""

from __future__ import annotations

import socket
from collections import Counter
from typing import TYPE_CHECKING

import numpy as np
import pytest

from drivers.fri import codec
from drivers.fri.backend import FriRobotConfig
from drivers.fri.convert import command_to_arrays, measurement_to_arrays
from drivers.fri.driver import FriRobot
from drivers.fri.types import CmdFlags, FriCommand, FriMeasurement, FriState

if TYPE_CHECKING:
    from drivers.description.scene import Scene

LOCAL = "127.0.0.1"
FOREIGN = "127.0.0.2"
TOTAL = 100_000
BATCH = 100


def udp(host: str) -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind((host, 0))
    s.settimeout(10.0)
    return s


def hostile(
    rng: np.random.Generator, valid: bytes, size: int, ident: int, seq_base: int, n: int,
    refl_fixed: int | None = None,
) -> list[tuple[bytes, bool]]:
    """``n`` datagrams and whether each goes out from the foreign address."""
    out: list[tuple[bytes, bool]] = []
    kinds = rng.integers(0, 7, n)
    for kind in kinds.tolist():
        if kind == 0:  # random bytes, random length (0 is a valid UDP payload)
            out.append((rng.bytes(int(rng.integers(0, 1400))), False))
        elif kind == 1:  # truncated
            out.append((valid[: int(rng.integers(0, size))], False))
        elif kind == 2:  # oversized
            out.append((valid + rng.bytes(int(rng.integers(1, 3000))), False))
        elif kind == 3:  # wrong datagramId
            b = bytearray(valid)
            bad = int(rng.integers(0, 0x10000))
            b[6:8] = (bad if bad != ident else ident ^ 1).to_bytes(2, "little")
            out.append((bytes(b), False))
        elif kind == 4:  # wrong packetSize
            b = bytearray(valid)
            b[4:6] = ((size + int(rng.integers(1, 1000))) & 0xFFFF).to_bytes(2, "little")
            out.append((bytes(b), False))
        elif kind == 5:  # valid header, random payload and sequence numbers near the base
            b = bytearray(rng.bytes(size))
            seq = (seq_base + int(rng.integers(-50, 51))) & 0xFFFF
            refl = int(rng.integers(0, 0x10000)) if refl_fixed is None else refl_fixed
            b[0:8] = (
                seq.to_bytes(2, "little") + refl.to_bytes(2, "little")
                + size.to_bytes(2, "little") + ident.to_bytes(2, "little")
            )
            out.append((bytes(b), False))
        else:  # well-formed, from a foreign address
            out.append((valid, True))
    return out


# --------------------------------------------------------------------------- the driver


@pytest.mark.slow
def test_driver_survives_and_counts_100k_hostile_datagrams() -> None:
    rng = np.random.default_rng(1)
    robot = FriRobot(
        FriRobotConfig(robot_ip=LOCAL, port=0, bind_host=LOCAL, answer_deadline_cycles=0.0)
    )
    krc, foreign = udp(LOCAL), udp(FOREIGN)
    try:
        _, port = robot.bind()
        dest = (LOCAL, port)
        robot.connect()
        arrays = codec.MsrArrays()
        measurement_to_arrays(FriMeasurement(state=FriState.MON), arrays)
        expected: Counter[codec.DecodeStatus] = Counter()
        sent = n_foreign = syncs = 0
        seq = 1000
        while sent < TOTAL:
            arrays.send_seq = seq
            valid = codec.encode_msr(arrays)
            batch = hostile(rng, valid, codec.MSR_SIZE, codec.MSR_DATAGRAM_ID, seq,
                            min(BATCH, TOTAL - sent))
            for data, from_foreign in batch:
                if from_foreign:
                    foreign.sendto(data, dest)
                    n_foreign += 1
                else:
                    krc.sendto(data, dest)
                    expected[codec.check_msr(data)] += 1
            sent += len(batch)
            seq = (seq + 200) & 0xFFFF  # a gap past every random sequence number
            arrays.send_seq = seq
            krc.sendto(codec.encode_msr(arrays), dest)
            expected[codec.DecodeStatus.OK] += 1
            syncs += 1
            while True:  # answers to random valid packets come first; ours is last
                data, _ = krc.recvfrom(2048)
                a = codec.CmdArrays()
                assert codec.decode_cmd_into(data, a) is codec.DecodeStatus.OK
                if a.refl_seq == seq:
                    break
            seq = (seq + 200) & 0xFFFF
        st = robot.stats
        assert robot._thread is not None and robot._thread.is_alive()
    finally:
        robot.close()
        krc.close()
        foreign.close()
    assert sent == TOTAL
    assert st.received == TOTAL + syncs
    assert st.foreign == n_foreign
    assert st.decode == {s.name.lower(): expected[s] for s in codec.DecodeStatus}
    assert st.decode["ok"] == st.accepted + st.duplicates + st.stale + st.implausible
    for s in codec.DecodeStatus:
        if s is not codec.DecodeStatus.OK:
            assert expected[s] > 1000, s  # every kind of rejection was exercised
    assert st.implausible > 1000 and st.accepted >= syncs


# --------------------------------------------------------------------------- the emulator


@pytest.mark.slow
def test_emulator_survives_and_counts_100k_hostile_datagrams(paper_scene: Scene) -> None:
    # imported here: the driver test above needs neither the emulator nor the simulator
    from drivers.fri.emulate.server import EmulatorSettings, FriEmulator
    from drivers.world.world import SimWorld

    rng = np.random.default_rng(2)
    remote, foreign = udp(LOCAL), udp(LOCAL)
    other = udp(FOREIGN)
    world = SimWorld(paper_scene, seed=0)
    emu: FriEmulator | None = None
    try:
        emu = FriEmulator(world, EmulatorSettings(
            remote=(LOCAL, remote.getsockname()[1]), bind_host=LOCAL, pacing="lockstep",
            lockstep_timeout_s=10.0))
        dest = emu.address
        emu.start_thread()
        cmd = codec.CmdArrays()
        expected: Counter[codec.DecodeStatus] = Counter()
        sent = n_foreign = syncs = 0
        send_seq = 5000
        msr = codec.MsrArrays()
        while sent < TOTAL:
            data, _ = remote.recvfrom(2048)  # the emulator's packet of this cycle
            assert codec.decode_msr_into(data, msr) is codec.DecodeStatus.OK
            command_to_arrays(
                FriCommand(flags=CmdFlags.CARTPOS, cart_pos=msr.cmd_cart_pos.copy()), cmd
            )
            cmd.refl_seq = msr.send_seq
            cmd.send_seq = send_seq
            valid = codec.encode_cmd(cmd)
            batch = hostile(rng, valid, codec.CMD_SIZE, codec.CMD_DATAGRAM_ID, send_seq,
                            min(BATCH, TOTAL - sent), refl_fixed=(msr.send_seq + 1000) & 0xFFFF)
            for d, from_foreign in batch:
                if from_foreign:
                    (other if rng.random() < 0.5 else foreign).sendto(d, dest)
                    n_foreign += 1
                else:
                    remote.sendto(d, dest)
                    expected[codec.check_cmd(d)] += 1
            sent += len(batch)
            send_seq = (send_seq + 200) & 0xFFFF
            cmd.send_seq = send_seq
            remote.sendto(codec.encode_cmd(cmd), dest)  # this cycle's answer, after the flood
            expected[codec.DecodeStatus.OK] += 1
            syncs += 1
            send_seq = (send_seq + 200) & 0xFFFF
        remote.recvfrom(2048)  # the last answer was taken: the world stepped
        st = emu.stats
        assert emu._thread is not None and emu._thread.is_alive()
    finally:
        if emu is not None:
            emu.close()
        remote.close()
        foreign.close()
        other.close()
    assert sent == TOTAL
    assert st.received == TOTAL + syncs
    assert st.foreign == n_foreign
    assert {k: v for k, v in st.decode.as_dict().items()} == {
        s.name.lower(): expected[s] for s in codec.DecodeStatus
    }
    assert st.answered == syncs and st.missed == 0
    assert st.decode.ok == st.answered + st.late + st.duplicates + st.stale
    assert st.late > 1000
    seqs = list(st.applied_seqs)
    assert len(seqs) == len(set(seqs))
