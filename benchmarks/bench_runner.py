"""One paper experiment in lockstep, against the bare world, in the same run.

    python benchmarks/bench_runner.py [--protocol P] [--seconds S] [--repeats R]

Runs the protocol (default Method I case I) for ``S`` seconds of simulated
time with the full runner (estimation, control, MCAP recording) and, for the
same simulated time, the bare world (``SimWorld.step`` + F/T read with a
constant command). Prints medians: wall time, real-time factor, where the
runner's time goes (driver = physics stepping, sensor + watchdogs,
estimation, control, recording), and the ratio runner/bare.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from drivers.base.types import CmdFlags, Command
from drivers.sim.driver import open_sim
from drivers.sim.scene import load_scene
from ffexp.protocol import load_run_protocol, scene_path
from ffexp.recording import Recorder
from ffexp.runner import Runner

ROOT = Path(__file__).resolve().parent.parent


def run_once(ppath: Path, seconds: float, out: Path) -> tuple[float, dict[str, float], float]:
    protocol = load_run_protocol(ppath, [f"run.timeout_s={seconds}", "run.stop_hold_s=0"])
    scene = load_scene(scene_path(ppath, protocol), protocol.scene.set)
    robot, sensor = open_sim(scene, seed=protocol.seed)
    t0 = time.perf_counter()
    with Recorder(out) as rec:
        runner = Runner(protocol, robot, sensor, rec, start_utc_ns=1_750_000_000 * 10**9)
        outcome = runner.run()
    wall = time.perf_counter() - t0
    return wall, dict(runner.timings), outcome.duration_s


def bare_once(ppath: Path, seconds: float) -> float:
    protocol = load_run_protocol(ppath)
    scene = load_scene(scene_path(ppath, protocol), protocol.scene.set)
    robot, _sensor = open_sim(scene, seed=protocol.seed)
    world = robot.world
    cmd = Command(
        flags=CmdFlags.TCPFT | CmdFlags.CARTSTIFF | CmdFlags.CARTDAMP | CmdFlags.CARTPOS,
        cart_pos=world.last_measurement.msr_cart_pos.copy(),
        cart_stiffness=np.asarray(protocol.krc.cart_stiffness),
        cart_damping=np.asarray(protocol.krc.cart_damping),
        add_tcp_ft=np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0]),
    )
    cycles = round(seconds / scene.fri.cycle)
    t0 = time.perf_counter()
    for _ in range(cycles):
        world.step(cmd)
        world.ft_samples()
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--protocol", type=Path, default=ROOT / "protocols/method1_case1.toml")
    ap.add_argument("--seconds", type=float, default=10.0, help="simulated time per run")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    walls, bares, parts = [], [], []
    sim_s = args.seconds
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.repeats):
            wall, timings, sim_s = run_once(args.protocol, args.seconds, Path(tmp) / f"{i}.mcap")
            walls.append(wall)
            parts.append(timings)
            bares.append(bare_once(args.protocol, sim_s))
    wall, bare = statistics.median(walls), statistics.median(bares)
    print(f"{args.protocol.name}: {sim_s:.2f} s simulated, {args.repeats} repeats (medians)")
    print(f"runner:     {wall:7.2f} s wall   real-time factor {sim_s / wall:6.1f}x")
    print(f"bare world: {bare:7.2f} s wall   real-time factor {sim_s / bare:6.1f}x")
    print(f"ratio runner/bare speed: {bare / wall:.2f}")
    total = sum(statistics.median(p[k] for p in parts) for k in parts[0])
    for key in parts[0]:
        part = statistics.median(p[key] for p in parts)
        print(f"  {key:<11} {part:7.2f} s  {100 * part / wall:5.1f} % of wall")
    print(f"  {'other':<11} {wall - total:7.2f} s  (set-up, phase changes, closing)")


if __name__ == "__main__":
    main()
