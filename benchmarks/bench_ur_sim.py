"""The simulated UR5e: a paper run in-process (``rigs/ur5e-sim.toml``) and over RTDE in lockstep
(``ffexp emulate --robot ur5e`` and ``rigs/ur5e-emulator.toml``) vs the bare world.

Each run is ``ffexp run PROTOCOL`` in a process of its own; its speed is simulated
seconds per wall second (the run's length from its last line, "after X s"). The
baseline is the bare world of the same scene (data/scenes/paper-ur5e.toml): the
simulated UR's force mode held on Z for as many cycles, nothing else (no program,
no driver, no estimator, no recording). Prints the three speeds and each run's ratio
to the bare world::

    .venv/bin/python benchmarks/bench_ur_sim.py [--protocol protocols/method1_case1.toml]
"""

from __future__ import annotations

import argparse
import os
import re
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PY = sys.executable
ENV = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}


def run(protocol: Path, rig: str, extra: list[str], out: Path) -> tuple[float, float, str]:
    """Simulated seconds, wall seconds and the outcome of one ``ffexp run``."""
    start = time.perf_counter()
    done = subprocess.run([PY, "-m", "ffexp", "run", str(protocol), "--rig", str(ROOT / rig),
                           *extra, "--out", str(out)], cwd=ROOT, env=ENV,
                          capture_output=True, text=True)
    wall = time.perf_counter() - start
    m = re.search(r"DONE \((.*?)\) after ([0-9.]+) s", done.stdout + done.stderr)
    if m is None:
        raise SystemExit(f"{rig}: no run end in its output:\n{done.stdout}{done.stderr}")
    return float(m.group(2)), wall, m.group(1)


def free_host() -> str:
    for i in range(40, 240):
        host = f"127.0.0.{i}"
        s = socket.socket()
        try:
            s.bind((host, 30004))
            return host
        except OSError:
            continue
        finally:
            s.close()
    raise SystemExit("no loopback address with a free port 30004")


def bare(seconds: float) -> float:
    """Wall seconds of the bare world for ``seconds`` of simulated time."""
    from drivers.description import load_scene
    from drivers.sim.ur_control import ForceModeCommand, UrArmControl
    from drivers.sim.world import SimWorld

    world = SimWorld(load_scene(ROOT / "data/scenes/paper-ur5e.toml"))
    arm = UrArmControl(world)
    cmd = ForceModeCommand(world.tcp_pose.copy(), np.array([0, 0, 1, 0, 0, 0], dtype=bool),
                           np.array([0, 0, 0.8, 0, 0, 0.0]), np.full(6, 0.1))
    cycles = round(seconds / world.cycle_s)
    start = time.perf_counter()
    for _ in range(cycles):
        world.advance(arm.command(cmd))
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--protocol", type=Path, default=ROOT / "protocols/method1_case1.toml")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        sim_s, wall_in, outcome_in = run(args.protocol, "rigs/ur5e-sim.toml",
                                         ["--rig-set", "robot.truth=false"], Path(tmp) / "in")
        host = free_host()
        emu = subprocess.Popen([PY, "-m", "ffexp", "emulate", "--robot", "ur5e", "--listen",
                                f"{host}:30004", "--pacing", "lockstep", "--seed", "1"],
                               cwd=ROOT, env=ENV, stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE, text=True)
        try:
            assert emu.stderr is not None
            while "UR5e controller" not in emu.stderr.readline():
                if emu.poll() is not None:
                    raise SystemExit("the emulator ended before it served")
            sim_w, wall_w, outcome_w = run(args.protocol, "rigs/ur5e-emulator.toml",
                                           ["--rig-set", f"robot.robot_ip={host}"],
                                           Path(tmp) / "wire")
        finally:
            emu.terminate()
            emu.wait(30)
    wall_bare = bare(sim_s)
    print(f"{args.protocol.name}: {sim_s:.2f} s simulated")
    print(f"  bare world        {sim_s / wall_bare:6.2f}x real time")
    for name, s, w, o in (("in-process", sim_s, wall_in, outcome_in),
                          ("RTDE lockstep", sim_w, wall_w, outcome_w)):
        print(f"  {name:17s} {s / w:6.2f}x real time, {(s / w) / (sim_s / wall_bare):.2f} of "
              f"the bare world; {o}")


if __name__ == "__main__":
    main()
