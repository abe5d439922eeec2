"""One paper experiment in lockstep, against bare physics and the bare world, in the same run.

    python benchmarks/bench_runner.py [--protocol P] [--seconds S] [--repeats R] [--zero-g P6]
                                      [--lean-only]

Runs the protocol (default Method I case I) for ``S`` seconds of simulated
time through ``ffexp.experiment.run_file`` on the built-in sim rig: the
lockstep KRC (``drivers.fri.emulate.lockstep``) with the sim F/T sensor, the
loop (estimator, safety, task, controller) and the MCAP recording. Baselines,
each measured in the same repeat:

* bare physics: the wall time of every ``mujoco.mj_step`` call inside that
  very run (the floor: the same model, the same states, the same steps);
* the loop without a recording (``RunLog(None)``), same protocol and seed;
* the bare world: ``SimWorld.step`` with a constant Cartesian command, its
  whole state read and the F/T read, for the same simulated time (no KRC,
  no loop).

Then the same ratio for a 6-DOF protocol on the zero-g scene (``--zero-g``, default
protocols/sixdof_method1.toml: RK4 on a free target), beside the first's.

Prints medians: wall time and real-time factor of each, the ratios, and where
the run's time goes (driver = the KRC and the world, of which physics; sensor
read; step = estimation, safety, task and control; send; recording). Then,
from one more run with a clock around each part (which adds ~0.3 us a call,
so its parts are a little high and that run is not timed as a whole), the
step's and the recording's parts in microseconds per cycle. That clock is the
calling thread's CPU time (``time.thread_time_ns``), not the wall clock: on
this shared two-core machine a cycle preempted by another process would
otherwise charge the wait to whichever part it was in.

Last, lean against full (a study's recording, ``run_file(lean=True)``), measured in
turn in the same session: the recording's thread CPU time per cycle (the run log's
``samples`` and ``cycle`` calls, what they frame included; instrumented runs, medians
of the repeats), the loop's own wall-clock part "recording" of runs not instrumented,
and the analysis of the file (``analysis.metrics(load(path))``, wall
time per run, the median of five reads of each file).
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import mujoco
import numpy as np

from drivers.description.scene import load_scene
from drivers.fri.emulate.lockstep import open_sim
from drivers.world.arm import ArmCommand, ArmMode
from drivers.world.world import SimWorld
from ffexp import loop
from ffexp.analysis import metrics
from ffexp.experiment import run_file
from ffexp.protocol import load_run_protocol, scene_path
from ffexp.recording import load
from ffexp.runlog import RunLog

ROOT = Path(__file__).resolve().parent.parent


@contextmanager
def timed_physics() -> Iterator[list[float]]:
    """Accumulate the wall time of every ``mujoco.mj_step`` call made inside the block."""
    total = [0.0]
    bare: Callable[..., None] = mujoco.mj_step
    clock = time.perf_counter

    def step(*args: object) -> None:
        t = clock()
        bare(*args)
        total[0] += clock() - t

    mujoco.mj_step = step
    try:
        yield total
    finally:
        mujoco.mj_step = bare


def run_once(ppath: Path, seconds: float, out: Path) -> tuple[float, dict[str, float], float]:
    timings: dict[str, float] = {}
    with timed_physics() as physics:
        t0 = time.perf_counter()
        result = run_file(ppath, [f"run.timeout_s={seconds}", "run.stop_hold_s=0"],
                          out_dir=out, timings=timings)
        wall = time.perf_counter() - t0
    timings["physics"] = physics[0]
    return wall, timings, result.outcome.duration_s


#: The parts of the step and of the recording, timed in the instrumented run:
#: (label, module, owner: a class or module in it, method); nested parts are inside
#: their parents; the writer frames the messages of many cycles at once, inside
#: whichever recording call fills its batch; the chunk compression runs beside the
#: loop, in the writer's thread.
PARTS = (
    ("step", "ffexp.loop", "Cycle", "step"),
    ("  estimator and safety checks", "ffexp.estimation", "Estimator", "update"),
    ("  safety's stop (when one holds)", "ffexp.safety", "SafetyMonitor", "stop_for"),
    ("  task", "ffexp.task", "Task", "step"),
    ("  approach law", "ffexp.controllers.base", "Approach", "command"),
    ("  align method", "ffexp.loop", "Cycle", "_align"),
    ("recording: F/T samples", "ffexp.runlog", "RunLog", "samples"),
    ("recording: cycle", "ffexp.runlog", "RunLog", "cycle"),
    ("  write_cycle (also in the sink)", "ffexp.recording.recorder", "Recorder",
     "write_cycle"),
    ("  3-D scene sink", "ffexp.scene3d.writer", "SceneWriter", "cycle"),
    ("  /tf encoding (also in the sink)", "ffexp.recording.recorder", "Recorder",
     "encode_transform"),
    ("recording: held messages framed", "ffexp.recording.mcap_writer",
     "FastWriter", "_drain"),
    ("chunk compression (worker thread)", "ffexp.recording", "mcap_writer", "_compress"),
)


@contextmanager
def timed_parts() -> Iterator[dict[str, list[int]]]:
    """Accumulate the CPU time of the calling thread [ns] and the calls of each of
    :data:`PARTS` inside the block."""
    import importlib

    acc: dict[str, list[int]] = {}
    undo: list[tuple[object, str, object]] = []
    clock = time.thread_time_ns
    for label, module, owner_name, method in PARTS:
        owner = getattr(importlib.import_module(module), owner_name)
        bare = getattr(owner, method)
        cell = acc[label] = [0, 0]

        def timed(*args: object, _bare: Callable[..., object] = bare,
                  _cell: list[int] = cell) -> object:
            t = clock()
            try:
                return _bare(*args)
            finally:
                _cell[0] += clock() - t
                _cell[1] += 1

        undo.append((owner, method, bare))  # a class's method or a module's function
        setattr(owner, method, timed)
    try:
        yield acc
    finally:
        for owner, name, bare in reversed(undo):
            setattr(owner, name, bare)


def unrecorded_once(ppath: Path, seconds: float) -> float:
    protocol = load_run_protocol(ppath, [f"run.timeout_s={seconds}", "run.stop_hold_s=0"])
    robot, sensor = open_sim(scene_path(ppath, protocol), seed=protocol.seed,
                             overrides=protocol.scene.set)
    t0 = time.perf_counter()
    loop.run(protocol, robot, sensor, RunLog(None, 0, protocol.run.tf_period_s))
    return time.perf_counter() - t0


def bare_world_once(ppath: Path, seconds: float) -> float:
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
        world.step(cmd).resolve()  # the whole state, as the lockstep KRC reads it
        world.ft_samples()
    return time.perf_counter() - t0


def zero_g_ratio(ppath: Path, seconds: float, repeats: int) -> float:
    """The median of a 6-DOF protocol's bare physics over its whole run (the same measure
    as the first protocol's speed ratio)."""
    ratios = []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(repeats):
            wall, timings, _ = run_once(ppath, seconds, Path(tmp) / f"z{i}")
            ratios.append(timings["physics"] / wall)
    return statistics.median(ratios)


#: The run log's calls that make a cycle's recording (the rest of PARTS is inside them).
RECORDING = ("recording: F/T samples", "recording: cycle")


def lean_against_full(ppath: Path, seconds: float, repeats: int) -> None:
    """Per cycle, the recording's thread CPU time and, per run, the analysis of the file:
    full and lean in turn, ``repeats`` times each; medians and their ratios."""
    cost: dict[bool, list[float]] = {False: [], True: []}
    wall: dict[bool, list[float]] = {False: [], True: []}
    analysis: dict[bool, list[float]] = {False: [], True: []}
    sizes: dict[bool, int] = {}
    cycles = 1
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(repeats):
            for lean in (False, True):
                with timed_parts() as acc:
                    result = run_file(ppath, [f"run.timeout_s={seconds}", "run.stop_hold_s=0"],
                                      out_dir=Path(tmp) / f"{lean}{i}", lean=lean)
                cycles = max(1, result.outcome.cycles)
                cost[lean].append(sum(acc[k][0] for k in RECORDING) / 1e3 / cycles)
                timings: dict[str, float] = {}  # and not instrumented: the loop's own clock
                run_file(ppath, [f"run.timeout_s={seconds}", "run.stop_hold_s=0"],
                         out_dir=Path(tmp) / f"{lean}{i}w", lean=lean, timings=timings)
                wall[lean].append(timings["recording"] * 1e6 / cycles)
                sizes[lean] = result.path.stat().st_size
                reads = []
                for _ in range(5):
                    t0 = time.perf_counter()
                    metrics(load(result.path))
                    reads.append(time.perf_counter() - t0)
                analysis[lean].append(statistics.median(reads))
    c_full, c_lean = statistics.median(cost[False]), statistics.median(cost[True])
    w_full, w_lean = statistics.median(wall[False]), statistics.median(wall[True])
    a_full, a_lean = statistics.median(analysis[False]), statistics.median(analysis[True])
    print(f"lean against full ({ppath.name}, {cycles} cycles, {repeats} repeats, medians):")
    print(f"  recording, thread CPU per cycle   full {c_full:7.1f} us   lean {c_lean:7.1f} us   "
          f"lean/full {c_lean / c_full:.2f}")
    print(f"  recording, loop's wall per cycle  full {w_full:7.1f} us   lean {w_lean:7.1f} us   "
          f"lean/full {w_lean / w_full:.2f}  (not instrumented)")
    print(f"  analysis (metrics(load(path)))    full {a_full * 1e3:7.1f} ms   lean "
          f"{a_lean * 1e3:7.1f} ms   lean/full {a_lean / a_full:.2f}  "
          f"({a_full / cycles * 1e6:.0f} / {a_lean / cycles * 1e6:.0f} us per cycle)")
    print(f"  file size                         full {sizes[False] / 1e6:7.2f} MB   lean "
          f"{sizes[True] / 1e6:7.2f} MB   lean/full {sizes[True] / sizes[False]:.2f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--protocol", type=Path, default=ROOT / "protocols/method1_case1.toml")
    ap.add_argument("--seconds", type=float, default=10.0, help="simulated time per run")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--zero-g", type=Path, default=ROOT / "protocols/sixdof_method1.toml",
                    help="a 6-DOF protocol on the zero-g scene: its ratio beside the first's")
    ap.add_argument("--lean-only", action="store_true",
                    help="only the lean-against-full comparison")
    args = ap.parse_args()
    if args.lean_only:
        lean_against_full(args.protocol, args.seconds, args.repeats)
        return
    walls, unrec, bares, parts = [], [], [], []
    sim_s = args.seconds
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.repeats):
            wall, timings, sim_s = run_once(args.protocol, args.seconds, Path(tmp) / str(i))
            walls.append(wall)
            parts.append(timings)
            unrec.append(unrecorded_once(args.protocol, sim_s))
            bares.append(bare_world_once(args.protocol, sim_s))
    wall = statistics.median(walls)
    part = {k: statistics.median(p[k] for p in parts) for k in parts[0]}
    physics = part.pop("physics")
    print(f"{args.protocol.name}: {sim_s:.2f} s simulated, {args.repeats} repeats (medians)")
    rows = (
        ("whole run (loop + KRC + sim F/T + recording)", wall),
        ("  its bare physics (mj_step calls of the run)", physics),
        ("loop without recording", statistics.median(unrec)),
        ("bare world (SimWorld.step + F/T, fixed command)", statistics.median(bares)),
    )
    for label, seconds in rows:
        print(f"{label:<48} {seconds:7.2f} s wall   real-time factor {sim_s / seconds:6.1f}x")
    print(f"ratio whole run / its bare physics (speed): {physics / wall:.2f}")
    planar_ratio = physics / wall
    print(f"ratio whole run / loop without recording:   {rows[2][1] / wall:.2f}")
    print(f"ratio whole run / bare world:               {rows[3][1] / wall:.2f}")
    print("where the whole run's time goes:")
    for key, seconds in part.items():
        print(f"  {key:<11} {seconds:7.2f} s  {100 * seconds / wall:5.1f} %")
        if key == "driver":
            print(f"    physics {physics:7.2f} s  {100 * physics / wall:5.1f} %  (mj_step)")
            rest = seconds - physics
            print(f"    rest    {rest:7.2f} s  {100 * rest / wall:5.1f} %"
                  "  (KRC emulation, world bookkeeping, F/T model)")
    print(f"  {'other':<11} {wall - sum(part.values()):7.2f} s  (set-up, phase changes, closing)")
    with tempfile.TemporaryDirectory() as tmp, timed_parts() as acc:
        timings = {}
        run_file(args.protocol, [f"run.timeout_s={args.seconds}", "run.stop_hold_s=0"],
                 out_dir=Path(tmp), timings=timings)
    zero_g = zero_g_ratio(args.zero_g, args.seconds, args.repeats)
    print(f"{args.zero_g.name} (zero-g, RK4): ratio whole run / its bare physics "
          f"{zero_g:.2f} against {planar_ratio:.2f} for {args.protocol.name} "
          f"({zero_g / planar_ratio:.2f}x)")
    cycles = max(1, round(sim_s / 0.005))
    print(f"parts of the step and the recording (one instrumented run, thread CPU time, "
          f"us per cycle of {cycles}; calls per cycle):")
    for label, (ns, calls) in acc.items():
        print(f"  {label:<36} {ns / 1e3 / cycles:7.1f} us  {calls / cycles:5.2f}")
    lean_against_full(args.protocol, args.seconds, args.repeats)


if __name__ == "__main__":
    main()
