"""A batch's physics dispatch, three ways: what one cycle of N runs costs per run.

    python benchmarks/bench_gate.py [--runs N] [--cycles K] [--repeats R]

N paper worlds (``data/scenes/paper.toml``, each its own model and data, the
target's lateral offset different per world), settled, then K cycles of the
scene's substeps each with the start command held (the world's own inputs: its
actuators hold the start pose). Per run and cycle, medians of R repeats:

* a loop of ``mj_step`` over the runs on one thread (what the gate does with one
  dispatch thread, without the gate);
* the gate (:class:`drivers.world.gate.PhysicsGate`): each run a greenlet that
  hands its cycle in, one dispatch a cycle, on 1 and on 2 threads (total, and the
  dispatch alone);
* ``mujoco.batch.Batch`` (``set_models``, 2 threads) with each run's full state
  (``mjSTATE_INTEGRATION``, the sensor history included) copied in from its data
  before the batch's ``step`` and back after: the Batch's speed with the runs'
  data kept as the worlds read them (still not a run's step: the quantities the
  step computes on the way, which the world reads after it, are not in the state).

Every path steps the same worlds from the same states; the loop and the gate end
bit for bit equal (checked), the Batch path too in the state (checked).
"""

from __future__ import annotations

import argparse
import functools
import os
import statistics
import time
from pathlib import Path

import mujoco
import mujoco.batch
import numpy as np

from drivers.description import load_scene
from drivers.world.gate import PhysicsGate
from drivers.world.world import SimWorld

ROOT = Path(__file__).resolve().parent.parent
FULL = mujoco.mjtState.mjSTATE_INTEGRATION


def worlds(n: int) -> list[SimWorld]:
    return [SimWorld(load_scene(ROOT / "data/scenes/paper.toml",
                                [f"target.lateral={0.008 + 0.001 * i:.3f}"]), seed=i)
            for i in range(n)]


def states(ws: list[SimWorld]) -> list[np.ndarray]:
    out = []
    for w in ws:
        s = np.empty(mujoco.mj_stateSize(w.model, FULL))
        mujoco.mj_getState(w.model, w.data, s, FULL)
        out.append(s)
    return out


def restore(ws: list[SimWorld], s0: list[np.ndarray]) -> None:
    for w, s in zip(ws, s0, strict=True):
        mujoco.mj_setState(w.model, w.data, s, FULL)


def loop(ws: list[SimWorld], cycles: int) -> float:
    t0 = time.perf_counter()
    for _ in range(cycles):
        for w in ws:
            mujoco.mj_step(w.model, w.data, w.substeps)
    return time.perf_counter() - t0


def gate(ws: list[SimWorld], cycles: int, threads: int) -> tuple[float, float]:
    g = PhysicsGate(threads)

    def body(w: SimWorld) -> None:
        for _ in range(cycles):
            g.step(w.model, w.data, w.substeps)

    t0 = time.perf_counter()
    g.run([functools.partial(body, w) for w in ws])
    return time.perf_counter() - t0, g.stats.physics_s


def batch(ws: list[SimWorld], cycles: int) -> float:
    b = mujoco.batch.Batch(ws[0].model, nsim=len(ws), nthread=2)
    b.set_models([w.model for w in ws])
    state = b.state
    buf = np.empty(state.shape[1])
    n = ws[0].substeps
    t0 = time.perf_counter()
    for _ in range(cycles):
        for i, w in enumerate(ws):
            mujoco.mj_getState(w.model, w.data, buf, FULL)
            state[i] = buf
        b.step(nstep=n)
        for i, w in enumerate(ws):
            buf[:] = state[i]
            mujoco.mj_setState(w.model, w.data, buf, FULL)
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=8)
    ap.add_argument("--cycles", type=int, default=400)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    ws = worlds(args.runs)
    s0 = states(ws)
    per = args.runs * args.cycles / 1e6  # run-cycles, in millions (-> us)
    res: dict[str, list[float]] = {k: [] for k in
                                   ("loop", "gate1", "gate1 dispatch", "gate2", "gate2 dispatch",
                                    "batch")}
    load0 = os.getloadavg()
    for _ in range(args.repeats):
        restore(ws, s0)
        res["loop"].append(loop(ws, args.cycles) / per)
        ref = states(ws)
        for threads in (1, 2):
            restore(ws, s0)
            total, phys = gate(ws, args.cycles, threads)
            res[f"gate{threads}"].append(total / per)
            res[f"gate{threads} dispatch"].append(phys / per)
            assert all(np.array_equal(a, b) for a, b in zip(states(ws), ref, strict=True))
        restore(ws, s0)
        res["batch"].append(batch(ws, args.cycles) / per)
        assert all(np.array_equal(a, b) for a, b in zip(states(ws), ref, strict=True))
    med = {k: statistics.median(v) for k, v in res.items()}
    print(f"{args.runs} paper worlds, {args.cycles} cycles of {ws[0].substeps} steps, "
          f"{args.repeats} repeats (medians), us per run and cycle:")
    print(f"  loop of mj_step, one thread                  {med['loop']:7.1f}")
    for t in (1, 2):
        print(f"  the gate, {t} thread(s), each run a greenlet   {med[f'gate{t}']:7.1f}  "
              f"(dispatch {med[f'gate{t} dispatch']:.1f})")
    print(f"  mujoco.batch.Batch, 2 threads, state in/out  {med['batch']:7.1f}")
    print("load average (1, 5, 15 min): before " + ", ".join(f"{x:.2f}" for x in load0)
          + "; after " + ", ".join(f"{x:.2f}" for x in os.getloadavg()))


if __name__ == "__main__":
    main()
