"""The experiment's control on the simulated rig: apparent inertia, the paper's methods."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from drivers.description.scene import load_scene
from drivers.fri.emulate.lockstep import open_sim
from ffexp.analysis import metrics
from ffexp.contracts import Phase
from ffexp.experiment import run_file
from ffexp.loop import Cycle
from ffexp.protocol import RunProtocol
from ffexp.recording import load
from ffexp.runlog import RunLog

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "data/scenes/paper.toml"


def free_tool_acceleration(k: float, force_n: float = 4.0) -> float:
    """Acceleration along TCF Y of the free tool pushed by an external force on the
    tool body, through the experiment's own cycle (estimator, contact detection, the
    force_ri controller with K_RI ``k`` on Y only).

    Joint friction off, the target out of reach, K = 0 on Y in the robot's impedance.
    """
    protocol = RunProtocol.model_validate({
        "name": "free-tool",
        "approach": {"speed_mps": 0.0, "stiffness": [0.0] * 6},
        "align": {"method": "force_ri", "force_axes": [False] * 6, "f_ref": [0.0] * 6,
                  "kp": [0.0] * 6, "ki": [0.0] * 6, "k_ri": [0.0, k, 0.0, 0.0, 0.0, 0.0]},
        "krc": {"cart_stiffness": [5000.0, 0.0, 5000.0, 300.0, 300.0, 300.0],
                "cart_damping": [0.7, 0.0, 0.7, 0.7, 0.7, 0.7]},
        "estimation": {"tool_load": {"mass_kg": 0.25}},
        "limits": {"max_speed_mps": 10.0, "workspace_m": [1.0, 1.0, 1.0]},
    })
    scene = load_scene(SCENE, ["arm.friction_scale=0", "target.distance=0.3"])
    robot, sensor = open_sim(scene, seed=0, start_cycles=0)
    world = robot.world
    tool = mujoco.mj_name2id(world.model, mujoco.mjtObj.mjOBJ_BODY, "tool")
    robot.connect()
    sensor.start()
    cyc: Cycle | None = None
    ts, ys = [], []
    y_axis = p0 = np.zeros(3)
    for i, state in enumerate(robot.measurements()):
        cyc = cyc or Cycle(protocol, state, RunLog(None, 0, 0.02))
        robot.send(cyc.step(state, sensor.samples()))
        if i == 80:  # tared at 0.25 s, in APPROACH: the "environment" pushes
            assert cyc.task.phase is Phase.APPROACH
            y_axis, p0 = state.tcp_pose_m[:3, 1].copy(), state.tcp_pose_m[:3, 3].copy()
            world.data.xfrc_applied[tool, :3] = force_n * y_axis
            t0 = cyc.t_ns
        elif i > 80:
            ts.append((cyc.t_ns - t0) / 1e9)
            ys.append(float(y_axis @ (state.tcp_pose_m[:3, 3] - p0)))
        if i == 141:
            break
    assert cyc is not None and cyc.task.phase is Phase.ALIGN  # the push was taken for contact
    t, y = np.array(ts), np.array(ys)
    late = t > 0.05  # past contact detection and the filter's settling
    return float(2.0 * np.polyfit(t[late], y[late], 2)[0])


@pytest.mark.slow
def test_apparent_inertia_reduction_on_the_simulated_arm() -> None:
    """Positive feedback k w on Y: the tool accelerates as if its mass were m / (1 + k)."""
    a0 = free_tool_acceleration(0.0)
    assert a0 > 0.1
    for k in (0.2, 1.0):
        assert free_tool_acceleration(k) / a0 == pytest.approx(1.0 + k, rel=0.05)


def run_protocol(tmp_path: Path, name: str, *overrides: str) -> tuple[Path, object]:
    result = run_file(ROOT / f"protocols/{name}.toml", list(overrides), out_dir=tmp_path)
    return result.path, result.outcome


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


@pytest.mark.slow
def test_admittance_runs_closed_loop_and_records_its_own_terms(tmp_path: Path) -> None:
    """The method the paper does not have, through the registry on the simulated rig."""
    path, _ = run_protocol(tmp_path, "admittance", "run.timeout_s=6")
    rec = load(path)
    terms = rec.topic("/control/admittance")
    phase = rec.topic("/control/terms")["phase"]
    assert len(terms) == int(np.sum(phase == Phase.ALIGN))  # written in ALIGN only
    # the virtual set-point integrates its velocity (x_k = x_{k-1} + dt v_k) within each ALIGN
    # segment, and starts from rest at each entry
    align = np.flatnonzero(phase == Phase.ALIGN)
    starts = np.concatenate([[0], np.flatnonzero(np.diff(align) != 1) + 1])
    x, v = terms["displacement"][:, 2], terms["velocity"][:, 2]
    for a, b in zip(starts, [*starts[1:], len(align)], strict=True):
        np.testing.assert_allclose(x[a], 0.005 * v[a], rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose(np.diff(x[a:b]), 0.005 * v[a + 1:b], rtol=1e-9, atol=1e-15)
    assert len(starts) >= 1 and np.max(np.abs(x)) > 1e-4  # it moved
    # and the command it sent is what the robot was asked for
    total = rec.topic("/control/terms")["total"][phase == Phase.ALIGN]
    intent = rec.topic("/control/command")["wrench"][phase == Phase.ALIGN]
    np.testing.assert_array_equal(total, intent)
    assert metrics(rec).first_contact_s is not None
