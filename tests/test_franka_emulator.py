"""The emulated FR3 (``ffexp emulate --robot fr3``) driven by Franka's own client and by
ffexp's Franka driver, each in a process of its own (libfranka's client blocks the
interpreter that would serve it), on a loopback address of its own; and the driver's
faults: each one line naming the address, the run ABORTed or the command exiting 1, and
the recording complete up to then.

Lockstep pacing makes the outcomes exact: the world steps on each command. Real-time
pacing's timing is a benchmark (benchmarks/bench_fci_link.py).
"""

from __future__ import annotations

import os
import re
import socket
import subprocess
import sys
import threading
from importlib.util import find_spec
from pathlib import Path

import numpy as np
import pytest
from test_rtde_ur_rtde import read_line

from drivers.franka import codec

ROOT = Path(__file__).resolve().parents[1]
FFEXP = [sys.executable, "-c", "from ffexp.cli import main; main()"]
pytestmark = pytest.mark.slow


def need(module: str) -> None:
    """Skip unless ``module`` (the test extra's) is installed. Not imported here: the clients
    run in processes of their own, and pylibfranka and franky, each with its own copy of
    libfranka's bindings, cannot both be imported into one interpreter."""
    if find_spec(module) is None:
        pytest.skip(f"{module} (the test extra) is not installed")


def free_host() -> str:
    """A 127.0.0.x whose port 1337 is free now (parallel runs pick different x)."""
    for i in range(200):
        host = f"127.0.{1 + (os.getpid() + i) % 200}.{7 + i % 50}"
        s = socket.socket()
        try:
            s.bind((host, codec.COMMAND_PORT))
            return host
        except OSError:
            continue
        finally:
            s.close()
    pytest.skip("no loopback address with a free port 1337")


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get(
        "PYTHONPATH", "")])}


def start_emulator(host: str, *args: str) -> subprocess.Popen[str]:
    """``ffexp emulate --robot fr3`` on ``host``, once it says it is ready."""
    proc = subprocess.Popen([*FFEXP, "emulate", "--robot", "fr3", "--listen",
                             f"{host}:{codec.COMMAND_PORT}", *args],
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, env=_env(), cwd=ROOT)
    seen = []
    for _ in range(5):
        line = read_line(proc, 120.0)
        seen.append(line)
        if "FR3 (libfranka protocol" in line:
            return proc
        if not line:
            break
    proc.kill()
    out, _ = proc.communicate(timeout=30)
    pytest.fail(f"the emulator did not start: {''.join(seen) + out!r}")


def stop(proc: subprocess.Popen[str]) -> str:
    proc.terminate()
    out, _ = proc.communicate(timeout=30)
    return out


CLIENT = r"""
import sys
import pylibfranka as plf
r = plf.Robot(sys.argv[1], plf.RealtimeConfig.kIgnore)
ids = [round(r.read_once().time.to_sec() * 1000) for _ in range(200)]
print("contiguous", all(b - a == 1 for a, b in zip(ids, ids[1:])), flush=True)
ctrl = r.start_torque_control()
for n in range(600):
    st, _ = ctrl.readOnce()
    if n == 299:
        print("q_hold", " ".join(repr(x) for x in st.q), flush=True)
    ctrl.writeOnce(plf.Torques([0.2 if 300 <= n < 500 else 0.0] + [0.0] * 6))
print("q_end", " ".join(repr(x) for x in st.q), flush=True)
print("success", st.control_command_success_rate, flush=True)
r.stop()
"""


SHORT_CLIENT = r"""
import sys
import pylibfranka as plf
r = plf.Robot(sys.argv[1], plf.RealtimeConfig.kIgnore)
ctrl = r.start_torque_control()
for n in range(50):
    st, _ = ctrl.readOnce()
    ctrl.writeOnce(plf.Torques([0.0] * 7))
r.stop()
"""


def test_a_motion_starts_and_stops_without_waiting_out_the_lockstep_timeout() -> None:
    # libfranka takes the motion's first state while it starts the motion and reads a newer
    # one before its first command; its stop comes over TCP while the emulator waits for a
    # UDP command. Each waited out the lockstep timeout (here 50 s: 100 s in all, beyond
    # the client's 60 s): the newer state is sent at once, and a stop ends the wait.
    need("pylibfranka")
    host = free_host()
    emu = start_emulator(host, "--pacing", "lockstep", "--timeout-ms", "50000")
    try:
        res = subprocess.run([sys.executable, "-c", SHORT_CLIENT, host], capture_output=True,
                             text=True, timeout=60)  # (before: TimeoutExpired)
    finally:
        out = stop(emu)
    assert res.returncode == 0, res.stderr
    summary = [line for line in out.splitlines() if "cycles;" in line][-1]
    counts = {k: int(v) for k, v in re.findall(r"(\w+) (\d+)(?= |$)", summary)}
    assert counts["answered"] == 50 and counts.get("missed", 0) == 0, summary
    assert counts.get("late", 0) == 0 and counts["states"] <= 60, summary


def _simulated(torques: list[np.ndarray], n_report: list[int]) -> list[np.ndarray]:
    """The simulated FR3 in-process under the same torques: q at the given cycles."""
    from drivers.description import load_scene
    from drivers.franka.emulate.controller import Fr3SimController
    from drivers.world.world import SimWorld

    scene = load_scene(ROOT / "data/scenes/paper-fr3.toml")
    c = Fr3SimController(SimWorld(scene, seed=scene.seed))
    c.start_motion()
    cmd = np.zeros((), dtype=codec.ROBOT_COMMAND)
    out = []
    for n, tau in enumerate(torques):
        rec = codec.decode(codec.ROBOT_STATE, c.state().tobytes())
        if n in n_report:
            out.append(np.asarray(rec["q"], dtype=np.float64))
        cmd["message_id"], cmd["tau_J_d"] = c.message_id, tau
        c.step(cmd)
    return out


def _client_lines(script: str) -> dict[str, str]:
    """Run a client ``script`` (given the host) in its own process against the emulator
    in lockstep; its ``name value`` lines."""
    host = free_host()
    emu = start_emulator(host, "--pacing", "lockstep")
    try:
        res = subprocess.run([sys.executable, "-c", script, host], capture_output=True,
                             text=True, timeout=300)
    finally:
        stop(emu)
    assert res.returncode == 0, res.stderr
    return dict(line.split(" ", 1) for line in res.stdout.splitlines())


def test_pylibfranka_reads_the_state_and_runs_a_torque_loop_in_lockstep() -> None:
    need("pylibfranka")
    lines = _client_lines(CLIENT)
    assert lines["contiguous"] == "True"
    assert float(lines["success"]) == 1.0
    torques = [np.array([0.2 if 300 <= n < 500 else 0.0] + [0.0] * 6) for n in range(600)]
    hold, end = _simulated(torques, [299, 599])
    got_hold = np.array([float(x) for x in lines["q_hold"].split()])
    got_end = np.array([float(x) for x in lines["q_end"].split()])
    assert np.array_equal(got_hold, hold) and np.array_equal(got_end, end)
    # zero torque holds the arm; the step turned joint 1 the way it pushed
    start = _simulated(torques[:1], [0])[0]
    assert np.array_equal(hold, start)
    assert end[0] - start[0] > 1e-3


def _numeric_topics(path: Path) -> dict[str, list[bytes]]:
    from mcap.reader import make_reader

    out: dict[str, list[bytes]] = {}
    with path.open("rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            if schema is not None and schema.encoding == "ros2msg":
                out.setdefault(channel.topic, []).append(message.data)
    return out


def test_method1_case1_over_the_emulator_in_lockstep_equals_in_process(tmp_path: Path) -> None:
    need("pylibfranka")
    host = free_host()
    rig_in = tmp_path / "in.toml"
    rig_in.write_text(f'[robot]\ntype = "franka-sim"\nscene_file = "{ROOT}/data/scenes/'
                      'paper-fr3.toml"\ntruth = false\n[ft]\ntype = "franka-wrench"\n')
    rig_emu = tmp_path / "emu.toml"
    rig_emu.write_text(f'[robot]\ntype = "franka"\nrobot_ip = "{host}"\nrealtime = "ignore"\n'
                       '[ft]\ntype = "franka-wrench"\n')
    protocol = ROOT / "protocols/method1_case1.toml"
    short = ["--set", "run.timeout_s=8"]  # 8 s of the approach and contact: 1600 cycles
    a = subprocess.run([*FFEXP, "run", str(protocol), "--rig", str(rig_in), "--out",
                        str(tmp_path / "a"), *short], capture_output=True, text=True,
                       env=_env(), timeout=600)
    assert a.returncode in (0, 4), a.stdout + a.stderr
    emu = start_emulator(host, "--pacing", "lockstep", "--seed", "1", "--timeout-ms", "30000")
    try:
        b = subprocess.run([*FFEXP, "run", str(protocol), "--rig", str(rig_emu), "--out",
                            str(tmp_path / "b"), *short], capture_output=True, text=True,
                           env=_env(), timeout=900)
    finally:
        stop(emu)
    assert b.returncode == a.returncode, b.stdout + b.stderr
    (ra,), (rb,) = (tmp_path / "a").glob("*.mcap"), (tmp_path / "b").glob("*.mcap")
    ta, tb = _numeric_topics(ra), _numeric_topics(rb)
    assert {"/robot/state", "/robot/franka", "/control/command", "/ft/raw"} <= set(ta)
    assert len(ta["/robot/state"]) > 1500
    assert ta.keys() == tb.keys()
    for topic in ta:
        assert ta[topic] == tb[topic], topic


def _run_against(tmp_path: Path, host: str) -> subprocess.CompletedProcess[str]:
    rig = tmp_path / "emu.toml"
    rig.write_text(f'[robot]\ntype = "franka"\nrobot_ip = "{host}"\nrealtime = "ignore"\n'
                   'connect_timeout_s = 1.0\n[ft]\ntype = "franka-wrench"\n')
    return subprocess.run([*FFEXP, "run", str(ROOT / "protocols/method1_case1.toml"), "--rig",
                           str(rig), "--out", str(tmp_path / "out")], capture_output=True,
                          text=True, env=_env(), timeout=600)


def _fault_line(res: subprocess.CompletedProcess[str]) -> str:
    """The one line saying why: the run's ABORT (a device that failed at connect is a run
    that never started: exit 3) or an ``error:`` line (exit 1)."""
    lines = [line for line in (res.stdout + res.stderr).splitlines()
             if line.startswith("error:") or ": ABORT (" in line]
    assert len(lines) == 1, res.stdout + res.stderr
    assert res.returncode == (1 if lines[0].startswith("error:") else 3), res.returncode
    return lines[0]


def test_a_robot_that_never_answers_is_one_line_naming_it(tmp_path: Path) -> None:
    need("pylibfranka")
    host = free_host()
    emu = start_emulator(host, "--fault", "silence=1")
    try:
        res = _run_against(tmp_path, host)
    finally:
        stop(emu)
    assert f"franka {host}:1337: no answer to Connect within 1 s" in _fault_line(res)


def test_an_incompatible_version_names_both(tmp_path: Path) -> None:
    """A tiny fake robot that answers every Connect with version 9, refusing ours."""
    need("pylibfranka")
    host = free_host()
    srv = socket.create_server((host, codec.COMMAND_PORT))

    def answer() -> None:
        srv.settimeout(60)
        conn, _ = srv.accept()
        with conn:
            req = codec.decode(codec.CONNECT_REQUEST, conn.recv(codec.CONNECT_REQUEST.itemsize))
            conn.sendall(codec.message(
                codec.CONNECT_RESPONSE, codec.Command.CONNECT, int(req["header"]["command_id"]),
                status=int(codec.ConnectStatus.INCOMPATIBLE_LIBRARY_VERSION), version=9))

    thread = threading.Thread(target=answer, daemon=True)
    thread.start()
    try:
        res = _run_against(tmp_path, host)
    finally:
        thread.join(10)
        srv.close()
    assert f"franka {host}:1337: incompatible version: the robot speaks 9, libfranka here 10" \
        in _fault_line(res)


@pytest.mark.parametrize(("fault", "words"), [
    ("drop_after=2000", "link lost: franka"),
    ("reflex_after=2000", "reflex: cartesian_reflex"),
])
def test_a_fault_mid_run_aborts_naming_the_robot_and_keeps_the_recording(
        tmp_path: Path, fault: str, words: str) -> None:
    need("pylibfranka")
    from ffexp.recording.reader import load

    host = free_host()
    emu = start_emulator(host, "--pacing", "lockstep", "--fault", fault)
    try:
        res = _run_against(tmp_path, host)
    finally:
        stop(emu)
    line = _fault_line(res)
    assert res.returncode == 3 and f"franka {host}:1337" in line and words in line
    (path,) = (tmp_path / "out").glob("*.mcap")
    rec = load(path)
    assert rec.complete
    # the run recorded every cycle until the fault: about 2 s of 5 ms cycles
    n = len(rec.topics["/robot/state"]["time_ns"])
    assert 300 <= n <= 420


FRANKY = r"""
import sys
import franky
robot = franky.Robot(sys.argv[1], realtime_config=franky.RealtimeConfig.Ignore)
robot.relative_dynamics_factor = 0.2
q0 = list(robot.current_joint_state.position)
target = list(q0)
target[0] += 0.1
target[6] -= 0.1
robot.move(franky.JointWaypointMotion([franky.JointWaypoint(target)]))
q = list(robot.current_joint_state.position)
print("error", max(abs(a - b) for a, b in zip(q, target)), flush=True)
print("moved", q[0] - q0[0], q[6] - q0[6], flush=True)
"""


def test_franky_runs_a_joint_motion_on_the_emulated_fr3() -> None:
    need("franky")
    lines = _client_lines(FRANKY)
    # the joint position servo holds the arm within a few mrad of franky's target
    assert float(lines["error"]) < 5e-3
    d0, d6 = (float(x) for x in lines["moved"].split())
    assert d0 == pytest.approx(0.1, abs=5e-3) and d6 == pytest.approx(-0.1, abs=5e-3)
