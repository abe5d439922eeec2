"""ur_rtde's RTDEReceiveInterface reads ``ffexp emulate --robot ur5e``: the simulator's values.

The emulated rig of ``ffexp emulate --robot ur5e`` (:class:`~drivers.emulate.session.EmulatedRig`
with the UR5e of data/scenes/paper-ur5e.toml, real-time pacing at 500 Hz) runs in a child
process (this file as a script: ur_rtde holds the GIL while it connects), on a loopback
address of its own (ur_rtde always connects to port 30004). The child records the values
the simulator produced at every step; ur_rtde reads ``timestamp``, ``actual_q``,
``actual_TCP_pose`` and ``actual_TCP_force`` at 500 Hz, and each read must be exactly the
simulator's at the step its timestamp names. ``FFEXP_UR_RTDE_S`` sets how long it reads
(default 2 s; the acceptance run: 60).
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from test_rtde_ur_rtde import free_loopback_host, read_line

ROOT = Path(__file__).resolve().parents[1]
VARIABLES = ("timestamp", "actual_q", "actual_TCP_pose", "actual_TCP_force")
READ_S = float(os.environ.get("FFEXP_UR_RTDE_S", "2"))


def serve(host: str, out: str) -> None:
    """The child: the emulated UR5e until stdin closes, then save what the world produced."""
    from drivers.description import load_scene
    from drivers.emulate.session import EmulatedRig, EmulatedRigSettings
    from drivers.ur.emulate.served import ServedUr

    scene = load_scene(ROOT / "data/scenes/paper-ur5e.toml")
    rows: dict[str, list[np.ndarray]] = {name: [] for name in VARIABLES}
    settings = EmulatedRigSettings(scene=scene, robot="ur5e", listen=(host, 30004),
                                   netft_port=None, pacing="realtime")
    with EmulatedRig(settings) as rig:
        assert isinstance(rig.served, ServedUr)
        server = rig.served.emulator.server
        step = server.source

        def recorded() -> dict[str, object]:
            values = step()
            for name in VARIABLES:
                rows[name].append(np.array(values[name], dtype=np.float64))
            return dict(values)

        server.source = recorded
        server.serve_in_thread()  # as the rig's serve() would start it
        print("ready", flush=True)
        sys.stdin.read()
    np.savez(out, **{name: np.array(v) for name, v in rows.items()})
    print("saved", flush=True)


@pytest.mark.slow
def test_ur_rtde_reads_the_simulated_ur5e_of_ffexp_emulate(tmp_path: Path) -> None:
    rtde_receive = pytest.importorskip(
        "rtde_receive", reason="ur_rtde (PyPI ur-rtde, the test extra) is not installed")
    import subprocess

    host = free_loopback_host()
    out = tmp_path / "produced.npz"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get(
        "PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, __file__, "serve", host, str(out)],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)
    samples: list[tuple[np.ndarray, ...]] = []
    try:
        assert read_line(proc, 60.0).strip() == "ready"
        receiver = rtde_receive.RTDEReceiveInterface(host, 500.0, list(VARIABLES))
        stamp = -1.0
        deadline = time.monotonic() + READ_S + 60.0
        while time.monotonic() < deadline:
            now = receiver.getTimestamp()
            if now == stamp:
                os.sched_yield()
                continue
            read = (np.array(now), np.array(receiver.getActualQ()),
                    np.array(receiver.getActualTCPPose()),
                    np.array(receiver.getActualTCPForce()))
            if receiver.getTimestamp() != now:
                continue  # a new package came while reading: the four may mix two steps
            samples.append(read)
            stamp = now
            if stamp >= READ_S:
                break
        receiver.disconnect()
    finally:
        assert proc.stdin is not None
        proc.stdin.close()
        status = read_line(proc, 60.0)
        proc.wait(30.0)
    assert status.strip() == "saved"
    table = np.load(out)
    times = table["timestamp"]
    assert samples and float(samples[-1][0]) >= READ_S
    for read in samples:
        k = int(np.flatnonzero(times == read[0])[0])  # the step of that instant
        for name, value in zip(VARIABLES[1:], read[1:], strict=True):
            np.testing.assert_array_equal(value, table[name][k], err_msg=f"{name} at step {k}")
    # the arm holds its start pose, the sensor reads the tool's weight and noise: the
    # values are the simulator's, not constants
    assert len({float(f[3][0]) for f in samples}) > 1
    print(f"ur_rtde read {len(samples)} packages over {float(samples[-1][0]):.2f} s")


if __name__ == "__main__" and sys.argv[1:2] == ["serve"]:
    serve(sys.argv[2], sys.argv[3])
