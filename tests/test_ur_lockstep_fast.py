"""The in-process UR's cheap per-cycle paths give what the field-by-field rules give.

The command written into an input record at once (in recipe order) against the same
command written field by field, the outputs of a controller cycle put into an output
record at once against field by field, and the input registers handed to the
controller from a record against each field's own value.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from drivers.base.types import CartesianCommand
from drivers.description import load_scene
from drivers.ur import registers
from drivers.ur.driver import OUTPUT_NAMES
from drivers.ur.emulate.controller import UrSimController
from drivers.ur.emulate.lockstep import LoopbackRtde
from drivers.ur.rtde.fields import Recipe
from drivers.ur.rtde.variables import INPUTS
from drivers.world.world import SimWorld

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "data" / "scenes" / "paper-ur5e.toml"


def _values(rec: np.ndarray) -> dict[str, object]:
    return {name: rec[name].tolist() for name in rec.dtype.names}


def _command(rng: np.random.Generator) -> CartesianCommand | None:
    if rng.random() < 0.2:
        return None
    pose = np.eye(4)
    axis = rng.normal(size=3)
    angle = rng.uniform(0.0, np.pi)
    k = axis / np.linalg.norm(axis)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    pose[:3, :3] = np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * kx @ kx
    pose[:3, 3] = rng.normal(0.0, 0.3, 3)
    stiffness = np.where(rng.random(6) < 0.5, 0.0, rng.uniform(100.0, 5000.0, 6))
    return CartesianCommand(pose, stiffness, rng.uniform(0.0, 1.0, 6), rng.normal(0.0, 10.0, 6))


@pytest.mark.parametrize("seed", range(4))
def test_a_command_written_at_once_equals_field_by_field(seed: int) -> None:
    rng = np.random.default_rng(seed)
    names = registers.INPUT_NAMES
    types = tuple(INPUTS[n] for n in names)
    at_once = Recipe(2, names, types).empty()
    # the same fields in another order: written one by one
    order = rng.permutation(len(names))
    by_field = Recipe(2, tuple(names[i] for i in order), tuple(types[i] for i in order)).empty()
    for k in range(40):
        cmd = _command(rng)
        seq = int(rng.integers(0, 2**33))
        kw = dict(stiffness_max=float(rng.choice([0.0, 200.0, 1e9])),
                  speed_limits=rng.uniform(0.01, 1.0, 6),
                  deviation_limits=rng.uniform(0.01, 1.0, 6),
                  damping=float(rng.random()), gain_scaling=float(rng.uniform(0, 2)),
                  lookahead_s=0.1, servo_gain=300.0)
        hold = _command(np.random.default_rng(k)) or CartesianCommand()
        a = registers.fill_command(at_once, seq, cmd, hold.pose_m, **kw)  # type: ignore[arg-type]
        b = registers.fill_command(by_field, seq, cmd, hold.pose_m, **kw)  # type: ignore[arg-type]
        assert a == b
        assert _values(at_once) == _values(by_field)


def test_outputs_and_inputs_cross_the_loopback_as_each_field() -> None:
    world = SimWorld(load_scene(SCENE), seed=2)
    controller = UrSimController(world)
    link = LoopbackRtde(controller)
    link.connect()
    outputs = link.setup_outputs(OUTPUT_NAMES, 500.0)
    inputs = link.setup_inputs(registers.INPUT_NAMES)
    link.start()
    rng = np.random.default_rng(5)
    record = inputs.empty()
    for k in range(30):
        pose = world.last_state.tcp_pose_m.copy()
        cmd = CartesianCommand(pose, np.array([0.0, 5000.0, 5000.0, 300.0, 300.0, 300.0]),
                               np.full(6, 0.5), rng.normal(0.0, 5.0, 6))
        registers.fill_command(record, k + 1, cmd, pose, stiffness_max=200.0,
                               speed_limits=np.full(6, 0.1), deviation_limits=np.full(6, 0.1),
                               damping=0.005, gain_scaling=1.0, lookahead_s=0.1, servo_gain=300)
        link.send(inputs, record)
        taken = controller.inputs  # (the driver's record: latched at once, in order)
        assert taken == {n: record[n].item() for n in inputs.names}
        assert [type(taken[n]) for n in inputs.names] == [
            type(record[n].item()) for n in inputs.names]
        pkg = link.receive_latest()
        values = controller.outputs()  # (the same state: the outputs again)
        ref = outputs.empty()
        for name in outputs.names:
            ref[name] = values[name]
        assert pkg.record.tobytes() == ref.tobytes()
