"""The runner's control on the simulated rig: apparent inertia, the paper's methods."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from drivers.base.types import CmdFlags, Command
from drivers.sim.driver import open_sim
from drivers.sim.scene import load_scene
from drivers.sim.world import SimWorld
from ffexp.analysis import metrics
from ffexp.control import ForceControlConfig, ForceController
from ffexp.estimation import (
    MotionFilter,
    MotionFilterConfig,
    ToolLoad,
    WrenchFilter,
    WrenchFilterConfig,
)
from ffexp.protocol import load_run_protocol, scene_path
from ffexp.recording import Recorder, load
from ffexp.runner import Runner

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "data/scenes/paper.toml"
CYCLE_S = 0.005


def free_tool_acceleration(k: float, force_n: float = 4.0) -> float:
    """Acceleration along TCF Y of the free tool pushed by an external force on
    the tool body, with the runner's estimation and K_RI feedback ``k`` on Y.

    Joint friction off, the target out of reach, K = 0 on Y in the KRC.
    """
    scene = load_scene(SCENE, ["arm.friction_scale=0", "target.distance=0.3"])
    world = SimWorld(scene, seed=0)
    pose0 = world.last_measurement.msr_cart_pos.copy()
    y_axis = pose0[:3, 1].copy()
    tool = mujoco.mj_name2id(world.model, mujoco.mjtObj.mjOBJ_BODY, "tool")
    load_ = ToolLoad(mass_kg=scene.tool.mass)
    ctl = ForceController(
        ForceControlConfig(
            force_axes=(False,) * 6, f_ref=(0.0,) * 6, kp=(0.0,) * 6, ki=(0.0,) * 6,
            k_ri=(0.0, k, 0.0, 0.0, 0.0, 0.0),
        ),
        CYCLE_S,
    )
    cmd = Command(
        flags=CmdFlags.TCPFT | CmdFlags.CARTPOS | CmdFlags.CARTSTIFF | CmdFlags.CARTDAMP,
        cart_pos=pose0,
        cart_stiffness=np.array([5000.0, 0.0, 5000.0, 300.0, 300.0, 300.0]),
        cart_damping=np.array([0.7, 0.0, 0.7, 0.7, 0.7, 0.7]),
    )
    wf = WrenchFilter(WrenchFilterConfig())
    mf = MotionFilter(MotionFilterConfig(), CYCLE_S)
    tare = []
    m = world.last_measurement
    for _ in range(50):
        m = world.step(cmd)
        mf.update(m.msr_cart_pos)
        tare.append(world.ft_samples().wrench - load_.wrench(m.msr_cart_pos[:3, :3]))
    wf.tare(np.concatenate(tare))
    p0 = m.msr_cart_pos[:3, 3].copy()
    world.data.xfrc_applied[tool, :3] = force_n * y_axis  # the "environment" pushes
    ts, ys = [], []
    t0 = world.time
    for _ in range(60):
        samples = world.ft_samples()
        r = m.msr_cart_pos[:3, :3]
        wf.update(samples.wrench - load_.wrench(r, mf.accel_base[:3]), CYCLE_S)
        cmd.add_tcp_ft[:] = ctl.update(wf.wrench).total
        m = world.step(cmd)
        mf.update(m.msr_cart_pos)
        ts.append(world.time - t0)
        ys.append(float(y_axis @ (m.msr_cart_pos[:3, 3] - p0)))
    t, y = np.array(ts), np.array(ys)
    late = t > 0.05  # past the filter's settling
    return float(2.0 * np.polyfit(t[late], y[late], 2)[0])


@pytest.mark.slow
def test_apparent_inertia_reduction_on_the_simulated_arm() -> None:
    """Positive feedback k w on Y: the tool accelerates as if its mass were m / (1 + k)."""
    a0 = free_tool_acceleration(0.0)
    assert a0 > 0.1
    for k in (0.2, 1.0):
        assert free_tool_acceleration(k) / a0 == pytest.approx(1.0 + k, rel=0.05)


def run_protocol(tmp_path: Path, name: str, *overrides: str) -> tuple[Path, object]:
    ppath = ROOT / f"protocols/{name}.toml"
    protocol = load_run_protocol(ppath, list(overrides))
    robot, sensor = open_sim(scene_path(ppath, protocol), seed=protocol.seed)
    path = tmp_path / f"{name}.mcap"
    with Recorder(path) as rec:
        outcome = Runner(protocol, robot, sensor, rec, start_utc_ns=1_750_000_000 * 10**9).run()
    return path, outcome


@pytest.mark.slow
def test_method3_impedance_breaks_contact_repeatedly(tmp_path: Path) -> None:
    path, _ = run_protocol(tmp_path, "method3_impedance", "run.timeout_s=20")
    m = metrics(load(path))
    assert m.first_contact_s is not None
    assert m.contact_breaks >= 2
    assert m.aborted is None


def smallest_aligning_f_ref(tmp_path: Path, name: str, grid: list[float]) -> float | None:
    for f_ref in sorted(grid):
        path, _ = run_protocol(
            tmp_path, name, f"align.f_ref=[0,0,{f_ref},0,0,0]", "run.timeout_s=20"
        )
        if metrics(load(path)).aligned:
            return f_ref
    return None


@pytest.mark.slow
def test_inertia_reduction_aligns_with_less_force(tmp_path: Path) -> None:
    """The paper's finding: the smallest f_ref that aligns is larger without
    apparent inertia reduction (Method II) than with it (Method I case I)."""
    grid = [0.8, 1.2, 1.5]
    with_ri = smallest_aligning_f_ref(tmp_path, "method1_case1", grid)
    without = smallest_aligning_f_ref(tmp_path, "method2", grid)
    assert with_ri is not None
    assert without is None or without > with_ri
