"""One paper experiment in lockstep, against the bare world, in the same run.

    python benchmarks/bench_runner.py [--protocol P] [--seconds S] [--repeats R]

Runs the protocol (default Method I case I) for ``S`` seconds of simulated
time through ``ffexp.experiment.run_file`` on the built-in sim rig (the loop:
estimator, safety, task, controller, MCAP recording) and, for the same
simulated time, the bare world (``SimWorld.step`` with a constant Cartesian
command + F/T read). Prints medians: wall time, real-time factor, where the
loop's time goes (driver = physics stepping, sensor read, step = estimation,
safety, task and control, send, recording) and the ratio loop/bare.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from drivers.sim.arm import ArmCommand, ArmMode
from drivers.sim.scene import load_scene
from drivers.sim.world import SimWorld
from ffexp.experiment import run_file
from ffexp.protocol import load_run_protocol, scene_path

ROOT = Path(__file__).resolve().parent.parent


def run_once(ppath: Path, seconds: float, out: Path) -> tuple[float, dict[str, float], float]:
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    result = run_file(ppath, [f"run.timeout_s={seconds}", "run.stop_hold_s=0"], out_dir=out,
                      timings=timings)
    wall = time.perf_counter() - t0
    return wall, timings, result.outcome.duration_s


def bare_once(ppath: Path, seconds: float) -> float:
    protocol = load_run_protocol(ppath)
    scene = load_scene(scene_path(ppath, protocol), protocol.scene.set)
    world = SimWorld(scene, seed=protocol.seed)
    cmd = ArmCommand(
        mode=ArmMode.CART_IMPEDANCE,
        cart_pose_m=world.last_state.tcp_pose_m.copy(),
        cart_stiffness_npm_nmprad=np.asarray(protocol.krc.cart_stiffness),
        cart_damping_ratio=np.asarray(protocol.krc.cart_damping),
        tcp_wrench_n_nm=np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0]),
    )
    cycles = round(seconds / scene.fri.cycle)
    t0 = time.perf_counter()
    for _ in range(cycles):
        world.step(cmd)
        world.ft_samples()
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--protocol", type=Path, default=ROOT / "protocols/method1_case1.toml")
    ap.add_argument("--seconds", type=float, default=10.0, help="simulated time per run")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    walls, bares, parts = [], [], []
    sim_s = args.seconds
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.repeats):
            wall, timings, sim_s = run_once(args.protocol, args.seconds, Path(tmp) / str(i))
            walls.append(wall)
            parts.append(timings)
            bares.append(bare_once(args.protocol, sim_s))
    wall, bare = statistics.median(walls), statistics.median(bares)
    print(f"{args.protocol.name}: {sim_s:.2f} s simulated, {args.repeats} repeats (medians)")
    print(f"loop:       {wall:7.2f} s wall   real-time factor {sim_s / wall:6.1f}x")
    print(f"bare world: {bare:7.2f} s wall   real-time factor {sim_s / bare:6.1f}x")
    print(f"ratio loop/bare speed: {bare / wall:.2f}")
    total = sum(statistics.median(p[k] for p in parts) for k in parts[0])
    for key in parts[0]:
        part = statistics.median(p[key] for p in parts)
        print(f"  {key:<11} {part:7.2f} s  {100 * part / wall:5.1f} % of wall")
    print(f"  {'other':<11} {wall - total:7.2f} s  (set-up, phase changes, closing)")


if __name__ == "__main__":
    main()
