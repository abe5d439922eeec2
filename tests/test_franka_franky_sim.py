"""ffexp's Franka driver against franky-sim, a server of libfranka's protocol no one here wrote
(its simulator in a process of its own, on a loopback address of its own): it connects,
holds the arm, runs a short impedance move towards a set-point 2 cm away and closes, with
no protocol error."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import numpy as np
import pytest
from test_franka_emulator import free_host, need
from test_rtde_ur_rtde import read_line

from drivers.base.types import CartesianCommand
from drivers.franka.config import FrankaSettings
from drivers.franka.driver import FrankaRobot

pytestmark = pytest.mark.slow


def _wait_ready(proc: subprocess.Popen[str], timeout_s: float) -> None:
    """Until franky-sim says where to connect (it serves one client at a time: no probe)."""
    deadline = time.monotonic() + timeout_s
    seen = []
    while time.monotonic() < deadline:
        line = read_line(proc, max(0.0, deadline - time.monotonic()))
        seen.append(line)
        if "Connect to the server" in line:
            return
        if not line and proc.poll() is not None:
            break
    pytest.fail(f"franky-sim did not start: {''.join(seen)!r}")


def test_the_driver_holds_and_moves_franky_sims_arm() -> None:
    need("pylibfranka")
    need("franky_sim")
    host = free_host()
    proc = subprocess.Popen([sys.executable, "-m", "franky_sim.run_server", "--simulator",
                             "mujoco", "--hostname", host], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        _wait_ready(proc, 180.0)
        robot = FrankaRobot(FrankaSettings(robot_ip=host, realtime="ignore",
                                           connect_timeout_s=30.0), where="test")
        robot.connect()
        try:
            states = robot.measurements()
            first = next(states)
            for _ in range(40):  # 0.2 s holding where it was
                robot.send(None)
                held = next(states)
            assert np.linalg.norm(held.tcp_pose_m[:3, 3] - first.tcp_pose_m[:3, 3]) < 2e-3
            target = held.tcp_pose_m.copy()
            target[:3, 3] += [0.02, 0.0, 0.0]
            cmd = CartesianCommand(pose_m=target, stiffness_npm_nmprad=np.array(
                [1500.0, 1500.0, 1500.0, 100.0, 100.0, 100.0]), damping_ratio=np.full(6, 0.9),
                wrench_n_nm=np.zeros(6))
            for _ in range(300):  # 1.5 s
                robot.send(cmd)
                last = next(states)
            moved = last.tcp_pose_m[0, 3] - held.tcp_pose_m[0, 3]
            assert 0.01 < moved < 0.03, moved
            assert last.link.commanding and last.link.healthy
        finally:
            robot.close()
    finally:
        proc.terminate()
        proc.communicate(timeout=30)
