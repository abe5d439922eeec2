"""Speed of the simulated world vs bare ``mj_step`` of the same model, same run.

    python benchmarks/bench_sim.py [--cycles N] [--repeats R] [--scene PATH]

Prints medians over the repeats: control cycles/s of ``SimWorld.step`` (with the
runner's F/T read each cycle), the physics steps/s that implies, bare
``mujoco.mj_step`` steps/s of the very same compiled model, the ratio of
the two, and the real-time factor.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import mujoco
import numpy as np

from drivers.sim import ArmCommand, SimWorld, load_scene

ROOT = Path(__file__).resolve().parent.parent


def bench_world(world: SimWorld, cycles: int, force: float) -> float:
    cmd = ArmCommand(tcp_wrench_n_nm=np.array([0.0, 0.0, force, 0.0, 0.0, 0.0]))
    t0 = time.perf_counter()
    for _ in range(cycles):
        world.step(cmd)
        world.ft_samples()
    return cycles / (time.perf_counter() - t0)


def bench_bare(world: SimWorld, steps: int) -> float:
    m = world.model
    d = mujoco.MjData(m)
    d.qpos[:] = world.data.qpos
    d.qvel[:] = world.data.qvel
    d.ctrl[:] = world.data.ctrl
    d.mocap_pos[:] = world.data.mocap_pos
    d.mocap_quat[:] = world.data.mocap_quat
    t0 = time.perf_counter()
    for _ in range(steps):
        mujoco.mj_step(m, d)
    return steps / (time.perf_counter() - t0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--cycles", type=int, default=1000, help="FRI cycles per repeat")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--scene", type=Path, default=ROOT / "data" / "scenes" / "paper.toml")
    args = ap.parse_args()
    base = load_scene(args.scene)
    cases = [
        ("free motion (target out of reach)", ["target.distance=0.5"], 0.5),
        ("push into the target (2 N)", [], 2.0),
    ]
    print(f"scene {args.scene.name}: physics dt {base.physics.timestep * 1e3:g} ms, "
          f"FRI cycle {base.fri.cycle * 1e3:g} ms ({base.substeps} steps/cycle), "
          f"{args.repeats} x {args.cycles} cycles per case, medians")
    for label, overrides, force in cases:
        scene = load_scene(args.scene, overrides)
        world_rates, bare_rates = [], []
        for _ in range(args.repeats):
            world = SimWorld(scene)
            world_rates.append(bench_world(world, args.cycles, force))
            bare_rates.append(bench_bare(world, args.cycles * world.substeps))
        cyc = statistics.median(world_rates)
        phys = cyc * scene.substeps
        bare = statistics.median(bare_rates)
        print(f"{label}:")
        print(f"  world: {cyc:8.0f} cycles/s = {phys:8.0f} physics steps/s "
              f"(real-time factor {cyc * scene.fri.cycle:5.1f}x)")
        print(f"  bare:  {bare:8.0f} mj_step/s of the same model and state "
              f"(real-time factor {bare * scene.physics.timestep:5.1f}x)")
        print(f"  ratio world/bare (physics steps/s): {phys / bare:.2f}")


if __name__ == "__main__":
    main()
