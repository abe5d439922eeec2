"""ffexp's Franka driver against franky-sim, a server of libfranka's protocol no one here wrote
(its simulator in a process of its own, on a loopback address of its own): it connects,
holds the arm, runs a short impedance move towards a set-point 2 cm away and closes, with
no protocol error."""

from __future__ import annotations

import subprocess
import sys
import time

import numpy as np
import pytest
from test_franka_emulator import free_host

from drivers.base.types import CartesianCommand
from drivers.franka.config import FrankaSettings
from drivers.franka.driver import FrankaRobot

pytestmark = pytest.mark.slow


def _wait_for_port(host: str, proc: subprocess.Popen[str], timeout_s: float) -> None:
    import socket

    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            pytest.fail(f"franky-sim ended: {proc.communicate()[0]}")
        try:
            with socket.create_connection((host, 1337), timeout=0.5):
                return
        except OSError:
            time.sleep(0.2)
    pytest.fail("franky-sim did not listen")


def test_the_driver_holds_and_moves_franky_sims_arm() -> None:
    pytest.importorskip("pylibfranka", reason="pylibfranka (the test extra) is not installed")
    pytest.importorskip("franky_sim", reason="franky-sim (the test extra) is not installed")
    host = free_host()
    proc = subprocess.Popen([sys.executable, "-m", "franky_sim.run_server", "--simulator",
                             "mujoco", "--hostname", host], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    try:
        _wait_for_port(host, proc, 120.0)
        robot = FrankaRobot(FrankaSettings(robot_ip=host, realtime="ignore",
                                           connect_timeout_s=10.0), where="test")
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
