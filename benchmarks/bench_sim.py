"""Speed of the simulated world vs bare ``mj_step`` of the same model, same run.

    python benchmarks/bench_sim.py [--cycles N] [--repeats R] [--scene PATH]

Three cases: holding still in free space (target out of reach, set-point at
the start pose, no wrench), moving in free space (a 1 N push along the
tool's Z, where the paper's stiffness is zero: the arm accelerates from
rest, latched one cycle before) and pressing into the funnel (the set-point
45 mm past the tool, reached after a warm-up). For each, in interleaved repeats from copies of
the same ``MjData``, medians of:

* ``SimWorld.advance`` + the F/T read: one FRI cycle of physics with the
  KRC's per-cycle work (command, damping from the Cartesian inertia, joint
  friction level, F/T samples, the end state's kinematics), no state built;
* ``SimWorld.step`` + the F/T read: the same plus the cycle's ``ArmState``
  (its fields are computed when first read: here none is);
* ``SimWorld.step`` + the F/T read + every field of the state read (joints,
  Jacobian, mass matrix, torques, ground truth): what the lockstep KRC reads;
* bare ``mujoco.mj_step`` of the very same compiled model and state, the
  same number of physics steps.

Prints each as physics steps/s, its real-time factor and the ratio to bare.
"""

from __future__ import annotations

import argparse
import copy
import statistics
import time
from pathlib import Path

import mujoco
import numpy as np

from drivers.description import load_scene
from drivers.world import ArmCommand, SimWorld
from drivers.world.arm import ArmState

ROOT = Path(__file__).resolve().parent.parent


def _read_all(state: ArmState) -> None:
    _ = state.jnt_pos_rad, state.jacobian, state.truth  # one field of each group


def _world_rate(world: SimWorld, cmd: ArmCommand, cycles: int, how: str) -> float:
    t0 = time.perf_counter()
    if how == "advance":
        for _ in range(cycles):
            world.advance(cmd)
            world.ft_samples()
    elif how == "step":
        for _ in range(cycles):
            world.step(cmd)
            world.ft_samples()
    else:
        for _ in range(cycles):
            _read_all(world.step(cmd))
            world.ft_samples()
    return cycles * world.substeps / (time.perf_counter() - t0)


def _bare_rate(m: mujoco.MjModel, d: mujoco.MjData, steps: int) -> float:
    step = mujoco.mj_step
    t0 = time.perf_counter()
    for _ in range(steps):
        step(m, d)
    return steps / (time.perf_counter() - t0)


def bench_case(scene_path: Path, overrides: list[str], push_m: float, force_n: float,
               warmup: int, cycles: int, repeats: int) -> dict[str, float]:
    """Median physics steps/s of advance, step, step with the state read and bare
    mj_step (interleaved)."""
    world = SimWorld(load_scene(scene_path, overrides))
    pose = world.last_state.tcp_pose_m.copy()
    pose[:3, 3] += push_m * pose[:3, 2]
    wrench = np.array([0.0, 0.0, force_n, 0.0, 0.0, 0.0])
    cmd = ArmCommand(cart_pose_m=pose, tcp_wrench_n_nm=wrench)
    # at least one cycle: the command's actuator inputs (ctrl, mocap) are in the
    # data every repeat starts from (the world rewrites only what changed)
    for _ in range(max(warmup, 1)):
        world.advance(cmd)
        world.ft_samples()
    start = copy.copy(world.data)
    rates: dict[str, list[float]] = {"advance": [], "step": [], "read": [], "bare": []}
    for _ in range(repeats):
        for key in rates:
            mujoco.mj_copyData(world.data, world.model, start)
            if key == "bare":
                d = copy.copy(start)
                rates[key].append(_bare_rate(world.model, d, cycles * world.substeps))
            else:
                rates[key].append(_world_rate(world, cmd, cycles, key))
    return {k: statistics.median(v) for k, v in rates.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--cycles", type=int, default=500, help="FRI cycles per repeat")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--scene", type=Path, default=ROOT / "data" / "scenes" / "paper.toml")
    args = ap.parse_args()
    base = load_scene(args.scene)
    dt = base.physics.timestep
    far = ["target.distance=0.5"]
    cases = [
        ("holding still in free space", far, 0.0, 0.0, 10),
        ("moving in free space (1 N push from rest)", far, 0.0, 1.0, 1),
        ("pressing into the funnel", [], 0.045, 1.0, 600),
    ]
    print(f"scene {args.scene.name}: physics dt {dt * 1e3:g} ms, FRI cycle "
          f"{base.fri.cycle * 1e3:g} ms ({base.substeps} steps/cycle), {args.repeats} x "
          f"{args.cycles} cycles per case, interleaved, medians")
    for label, overrides, push_m, force_n, warmup in cases:
        r = bench_case(args.scene, overrides, push_m, force_n, warmup, args.cycles,
                       args.repeats)
        bare = r["bare"]
        print(f"{label}:")
        print(f"  bare mj_step:       {bare:8.0f} steps/s  real-time factor {bare * dt:6.1f}x")
        for key, what in (("advance", "advance + F/T"), ("step", "step + F/T"),
                          ("read", "step + F/T + read")):
            print(f"  {what:<19} {r[key]:8.0f} steps/s  real-time factor {r[key] * dt:6.1f}x"
                  f"  ratio to bare {r[key] / bare:.2f}")


if __name__ == "__main__":
    main()
