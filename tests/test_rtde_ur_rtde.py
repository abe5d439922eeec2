"""ur_rtde, an independent RTDE client, reads and writes our RTDE server: it speaks RTDE.

ur_rtde's ``RTDEReceiveInterface`` connects to port 30004 of the host it is
given (the port cannot be chosen), so the server listens on a loopback
address of its own (127.0.0.x). ur_rtde holds the GIL while it connects, so
the server runs in a child process: this file run as a script
(``python tests/test_rtde_ur_rtde.py serve HOST STEPS OUT``). Its data source
records every step it produced; after ``STEPS`` steps it holds still (the
same values every cycle, as a robot at rest). The test reads
``timestamp``, ``actual_q``, ``actual_TCP_pose`` and ``actual_TCP_force``
while the values change and checks that each one read is one the source
produced, then that the four read at rest are the last step's, all exactly.
ur_rtde's ``RTDEIOInterface`` writes input registers and digital outputs
(input recipes, input data packages), which the server's sink records.
"""

from __future__ import annotations

import json
import os
import select
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
VARIABLES = ("timestamp", "actual_q", "actual_TCP_pose", "actual_TCP_force")
STEPS = 1000  # 2 s at 500 Hz


def produced(k: int) -> dict[str, np.ndarray]:
    """The source's values at step k: each vector tells its step."""
    return {"timestamp": np.array(k * 0.002),
            "actual_q": k * 1e-3 + np.arange(6) / 8,
            "actual_TCP_pose": np.array([0.4, 0.1, 0.3, 0.0, 3.1, 0.0]) + k * 1e-5,
            "actual_TCP_force": -np.arange(6) - k * 0.5}


def serve(host: str, steps: int, out: str) -> None:
    """The child: serve until stdin closes, then save what the source produced."""
    from drivers.ur.emulate.rtde_server import RtdeServer

    rows: dict[str, list[np.ndarray]] = {name: [] for name in VARIABLES}

    def source() -> dict[str, np.ndarray]:
        k = min(len(rows["timestamp"]), steps - 1)
        values = produced(k)
        if len(rows["timestamp"]) < steps:
            for name in VARIABLES:
                rows[name].append(values[name])
        return values

    inputs: list[dict[str, object]] = []

    def sink(values: Any) -> None:
        inputs.append({k: v.tolist() if isinstance(v, np.ndarray) else v
                       for k, v in values.items()})

    with RtdeServer(source, sink, host=host, pacing="realtime", outputs=VARIABLES) as srv:
        print("ready", flush=True)
        sys.stdin.read()
        counters = dict(srv.counters)
    np.savez(out, **{name: np.array(v) for name, v in rows.items()})
    Path(out).with_suffix(".json").write_text(json.dumps(inputs))
    print(f"saved {counters}", flush=True)


def free_loopback_host() -> str:
    """A 127.0.0.x whose port 30004 is free now (parallel runs pick different x)."""
    for i in range(200):
        host = f"127.0.0.{20 + (os.getpid() + i) % 200}"
        s = socket.socket()
        try:
            s.bind((host, 30004))
            return host
        except OSError:
            continue
        finally:
            s.close()
    pytest.skip("no loopback address with a free port 30004")


def read_line(proc: subprocess.Popen[str], timeout_s: float) -> str:
    assert proc.stdout is not None
    ready, _, _ = select.select([proc.stdout], [], [], timeout_s)
    return proc.stdout.readline() if ready else ""


def row_of(table: np.ndarray, value: np.ndarray) -> int:
    """The step whose produced row equals ``value`` exactly (-1: none)."""
    hits = np.flatnonzero(np.all(table.reshape(len(table), -1) == value.reshape(1, -1), axis=1))
    return int(hits[0]) if hits.size else -1


def start_server(host: str, out: Path) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get(
        "PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, __file__, "serve", host, str(STEPS), str(out)],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)
    assert read_line(proc, 60.0).strip() == "ready"
    return proc


def stop_server(proc: subprocess.Popen[str]) -> str:
    """Close the child's stdin; its last line ("saved ...")."""
    assert proc.stdin is not None
    proc.stdin.close()
    status = read_line(proc, 30.0)
    proc.wait(30.0)
    return status


def test_ur_rtdes_io_interface_writes_inputs_our_server_reads(tmp_path: Path) -> None:
    rtde_io = pytest.importorskip(
        "rtde_io", reason="ur_rtde (PyPI ur-rtde, the test extra) is not installed")
    host = free_loopback_host()
    out = tmp_path / "produced.npz"
    proc = start_server(host, out)
    try:
        io = rtde_io.RTDEIOInterface(host)  # sets up one input recipe per kind of write
        assert io.setInputIntRegister(18, -42)
        assert io.setInputDoubleRegister(19, 1.5)
        assert io.setStandardDigitalOut(2, True)
        io.disconnect()
    finally:
        status = stop_server(proc)
    assert status.startswith("saved"), status
    got = json.loads(out.with_suffix(".json").read_text())
    # every input package carries ur_rtde's own register 23 beside the value written
    assert [{k: v for k, v in g.items() if k != "input_int_register_23"} for g in got] == [
        {"input_int_register_18": -42}, {"input_double_register_19": 1.5},
        {"standard_digital_output_mask": 4, "standard_digital_output": 4}]


@pytest.mark.slow
def test_ur_rtde_reads_exactly_what_the_source_produced(tmp_path: Path) -> None:
    rtde_receive = pytest.importorskip(
        "rtde_receive", reason="ur_rtde (PyPI ur-rtde, the test extra) is not installed")
    host = free_loopback_host()
    out = tmp_path / "produced.npz"
    proc = start_server(host, out)
    samples: list[tuple[np.ndarray, ...]] = []
    try:
        receiver = rtde_receive.RTDEReceiveInterface(host, 500.0, list(VARIABLES))
        last = (STEPS - 1) * 0.002
        deadline = time.monotonic() + 60.0
        stamp = -1.0
        while stamp != last and time.monotonic() < deadline:
            if receiver.getTimestamp() == stamp:
                os.sched_yield()  # nothing new: let the server's process run
                continue
            read = (np.array(receiver.getTimestamp()), np.array(receiver.getActualQ()),
                    np.array(receiver.getActualTCPPose()), np.array(receiver.getActualTCPForce()))
            samples.append(read)
            stamp = float(read[0])
        # at rest: one package repeated, so the four reads are of one step
        at_rest = (np.array(receiver.getTimestamp()), np.array(receiver.getActualQ()),
                   np.array(receiver.getActualTCPPose()), np.array(receiver.getActualTCPForce()))
        receiver.disconnect()
    finally:
        status = stop_server(proc)
    assert status.startswith("saved"), status
    table = np.load(out)
    assert len(table["timestamp"]) == STEPS
    steps_seen = set()
    for read in samples:
        rows = [row_of(table[name], value) for name, value in zip(VARIABLES, read, strict=True)]
        assert min(rows) >= 0, f"read values the source never produced: {read}"
        steps_seen.add(rows[0])
    assert len(steps_seen) >= 2 and max(steps_seen) == STEPS - 1
    print(f"ur_rtde read {len(samples)} packages, {len(steps_seen)} distinct steps")
    for name, value in zip(VARIABLES, at_rest, strict=True):
        np.testing.assert_array_equal(value, table[name][-1])


if __name__ == "__main__" and sys.argv[1:2] == ["serve"]:
    serve(sys.argv[2], int(sys.argv[3]), sys.argv[4])
