"""A study's throughput today against the bare batched physics of the very same runs.

    python benchmarks/bench_study.py [--runs R] [--seconds S] [--workers N] [--repeats K]
                                     [--batch B] [--lean]
    python benchmarks/bench_study.py --recording [--runs R]
    python benchmarks/bench_study.py --estimator [--runs R]

The study: R runs of the paper's methods (Method I case I and II, Method II,
Method III; the protocols in turn, one noise seed each), ``run.timeout_s=S``,
recorded full (``--lean``: lean, as ``ffexp limits`` and ``reproduce`` record).
Measured in the same process, interleaved per repeat:

* **today's pool**: the sweep engine on ``local:N`` (run, analyse, commit each
  run in a worker process, as ``ffexp sweep`` does); its workers' start-up is
  timed apart and not counted;
* **batched study**: the same study through ``--executor local:N,batch:B``
  (:mod:`ffexp.sweeps.batch`): N processes, each running batches of up to B runs
  in lockstep, every run's own code unchanged (a greenlet each), the physics of
  a batch's live runs one dispatch a cycle (:class:`drivers.world.gate.PhysicsGate`);
  its workers' start-up is not counted either;
* **bare batched physics** of the same runs: every run's own physics replayed
  with no controller and no recording. Each run is first made once in this
  process with ``mujoco.mj_step`` wrapped, which records the run's model, its
  state before its first step (``mjSTATE_INTEGRATION``, a Batch row) and what it
  wrote before every call (``ctrl``, ``qfrc_applied``, ``xfrc_applied``, the
  mocap pose, and the model fields the simulator rewrites each cycle: the joint
  friction's dry level and the actuators' gains), with that call's number of
  substeps. The replay writes those into a ``mujoco.batch.Batch`` of all the
  runs (each run on its own model via ``set_models``) and steps the runs still
  going with one ``step`` call per recorded call, as a batched closed loop
  would: the floor a batched study of these runs can reach on this machine;
* the same replay on one thread as a plain loop of ``mj_step`` per run (what
  one core gives without the batch), for scale.

Throughput is simulated seconds per wall second over the whole study. Prints
medians, each path's throughput as a fraction of the bare batched physics (the
issue's target for a batched pipeline is at least 0.7 of it) and of today's pool
(the target: at least 2), and the largest joint-position difference between a
replayed run and the recorded one at its end (0 when the replay is the runs'
physics bit for bit, as it is here).

Then, once, where a batch's time goes: B runs as one batch in this process
(``run_batch``, one dispatch thread) against the same B runs one after the other
(``run_one``), with the share of the batch's wall time its physics dispatches
took (the dispatch's options: ``benchmarks/bench_gate.py``).

``--recording`` measures only the recording's cost per run and cycle for R runs,
on a paper run's own messages: the fixed-layout topics encoded one run at a time
against :class:`ffexp.recording.batch.BatchEncoder` for the batch at once, and each
run's cycle written to its own file, all topics or a lean recording's.

``--estimator`` measures only the estimator's cost per run and cycle, on a paper run's
own inputs (its poses, F/T samples, link state and times, captured once): R runs each
stepped alone (an :class:`~ffexp.estimation.Estimator` each, a batch of one, as a run
today) against one estimator of the R runs (``update_batch``, the runs' inputs packed
into its arrays each cycle, the packing counted), the runs offset in the paper run
and with different tool loads; then the compiled cycle's costs of a fresh process:
importing numba, compiling (an empty cache) and loading the compiled code from the
on-disk cache.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Executor
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import mujoco
import mujoco.batch
import numpy as np

from ffexp.experiment import run_file
from ffexp.sweeps import engine
from ffexp.sweeps.executors import PRELOAD, available_cpus, make_executor, parse_executor
from ffexp.sweeps.worker import Job

ROOT = Path(__file__).resolve().parent.parent
PROTOCOLS = ("method1_case1", "method1_case2", "method2", "method3_impedance")
#: The state a replay starts from: a Batch's row (mjSTATE_INTEGRATION: the full physics
#: state, sensor history included, and the inputs).
FULL = mujoco.mjtState.mjSTATE_INTEGRATION


@dataclass
class Capture:
    """One run's physics: its model, first state and per-call inputs."""

    model: mujoco.MjModel
    state0: np.ndarray
    nstep: list[int] = field(default_factory=list)
    ctrl: list[np.ndarray] = field(default_factory=list)
    qfrc: list[np.ndarray] = field(default_factory=list)
    xfrc: list[np.ndarray] = field(default_factory=list)
    mocap_pos: list[np.ndarray] = field(default_factory=list)
    mocap_quat: list[np.ndarray] = field(default_factory=list)
    frictionloss: list[np.ndarray] = field(default_factory=list)
    gain: list[np.ndarray] = field(default_factory=list)
    bias: list[np.ndarray] = field(default_factory=list)
    qpos_end: np.ndarray | None = None

    @property
    def steps(self) -> int:
        return sum(self.nstep)

    @property
    def sim_s(self) -> float:
        return self.steps * float(self.model.opt.timestep)


@contextmanager
def capturing() -> Iterator[dict[int, Capture]]:
    """Wrap ``mujoco.mj_step``: per MjData, the model, first state and inputs of every call."""
    caps: dict[int, Capture] = {}
    keep: list[mujoco.MjData] = []  # ids stay unique while the block runs
    real = mujoco.mj_step

    def step(m: mujoco.MjModel, d: mujoco.MjData, nstep: int = 1) -> None:
        cap = caps.get(id(d))
        if cap is None:
            keep.append(d)
            state = np.empty(mujoco.mj_stateSize(m, FULL))
            mujoco.mj_getState(m, d, state, FULL)
            cap = caps[id(d)] = Capture(model=m, state0=state)
        cap.nstep.append(nstep)
        cap.ctrl.append(d.ctrl.copy())
        cap.qfrc.append(d.qfrc_applied.copy())
        cap.xfrc.append(d.xfrc_applied.copy())
        cap.mocap_pos.append(d.mocap_pos.copy())
        cap.mocap_quat.append(d.mocap_quat.copy())
        cap.frictionloss.append(m.dof_frictionloss.copy())
        cap.gain.append(m.actuator_gainprm[:, 0].copy())
        cap.bias.append(m.actuator_biasprm[:, :3].copy())
        real(m, d, nstep)
        cap.qpos_end = d.qpos.copy()

    mujoco.mj_step = step  # type: ignore[assignment]
    try:
        yield caps
    finally:
        mujoco.mj_step = real  # type: ignore[assignment]


def make_jobs(out: Path, runs: int, seconds: float, lean: bool = False) -> list[Job]:
    jobs = []
    for i in range(runs):
        name = PROTOCOLS[i % len(PROTOCOLS)]
        seed = i // len(PROTOCOLS)
        jobs.append(Job(run_id=f"{name}-s{seed}", protocol=str(ROOT / f"protocols/{name}.toml"),
                        overrides=(f"run.timeout_s={seconds}", f"seed={seed}"),
                        out_dir=str(out), columns={"protocol": name, "seed": seed},
                        lean=lean))
    return jobs


def capture_runs(jobs: list[Job], tmp: Path) -> list[Capture]:
    """Make each run once in this process and keep its physics (the MjData that stepped most)."""
    out = []
    for k, job in enumerate(jobs):
        with capturing() as caps:
            run_file(Path(job.protocol), list(job.overrides), out_dir=tmp / f"cap{k}")
        out.append(max(caps.values(), key=lambda c: c.steps))
    return out


def replay_batched(caps: list[Capture], nthread: int) -> float:
    """Wall time of all runs' physics in one Batch, one ``step`` call per recorded call."""
    b = mujoco.batch.Batch(caps[0].model, nsim=len(caps), nthread=nthread)
    b.set_models([c.model for c in caps])
    state = b.state
    for i, c in enumerate(caps):
        state[i] = c.state0
    views = {name: b.bind(name) for name in
             ("ctrl", "qfrc_applied", "xfrc_applied", "mocap_pos", "mocap_quat")}
    ncall = max(len(c.nstep) for c in caps)
    # Inputs laid out per call (runs that ended hold their last call): no Python per run
    # inside the timed loop beyond picking the rows still going.
    def stack(attr: str) -> np.ndarray:
        return np.stack([np.stack(getattr(c, attr) + [getattr(c, attr)[-1]]
                                  * (ncall - len(c.nstep))) for c in caps], axis=1)
    inputs = {"ctrl": stack("ctrl"), "qfrc_applied": stack("qfrc"),
              "xfrc_applied": stack("xfrc"), "mocap_pos": stack("mocap_pos"),
              "mocap_quat": stack("mocap_quat")}
    # What the simulator writes into its model per cycle: the joint friction's dry level
    # and the actuators' gains (the commanded impedance).
    friction, gain, bias = stack("frictionloss"), stack("gain"), stack("bias")
    models = [c.model for c in caps]
    nstep = np.zeros((ncall, len(caps)), dtype=np.int64)
    for i, c in enumerate(caps):
        nstep[:len(c.nstep), i] = c.nstep
    # Group the runs of each call by their number of substeps (one Batch.step per group).
    plan: list[list[tuple[int, np.ndarray]]] = []
    for k in range(ncall):
        row = nstep[k]
        plan.append([(int(n), np.flatnonzero(row == n)) for n in np.unique(row[row > 0])])
    t0 = time.perf_counter()
    for k in range(ncall):
        for name, view in views.items():
            view[...] = inputs[name][k]
        for i, m in enumerate(models):
            m.dof_frictionloss[:] = friction[k, i]
            m.actuator_gainprm[:, 0] = gain[k, i]
            m.actuator_biasprm[:, :3] = bias[k, i]
        for n, ids in plan[k]:
            b.step(ids=ids if ids.size < len(caps) else None, nstep=n)
    wall = time.perf_counter() - t0
    qpos = b.bind("qpos")
    drift = max(float(np.max(np.abs(qpos[i] - c.qpos_end))) for i, c in enumerate(caps)
                if c.qpos_end is not None)
    REPLAY_DRIFT.append(drift)
    return wall


#: The replay's largest joint-position difference from the recorded run at its end.
REPLAY_DRIFT: list[float] = []


def replay_loop(caps: list[Capture]) -> float:
    """Wall time of the same replay as a plain ``mj_step`` loop per run, on this thread."""
    datas = []
    for c in caps:
        d = mujoco.MjData(c.model)
        mujoco.mj_setState(c.model, d, c.state0, FULL)
        datas.append(d)
    t0 = time.perf_counter()
    for c, d in zip(caps, datas, strict=True):
        m = c.model
        for k, n in enumerate(c.nstep):
            d.ctrl[:] = c.ctrl[k]
            d.qfrc_applied[:] = c.qfrc[k]
            d.xfrc_applied[:] = c.xfrc[k]
            d.mocap_pos[:] = c.mocap_pos[k]
            d.mocap_quat[:] = c.mocap_quat[k]
            m.dof_frictionloss[:] = c.frictionloss[k]
            m.actuator_gainprm[:, 0] = c.gain[k]
            m.actuator_biasprm[:, :3] = c.bias[k]
            mujoco.mj_step(m, d, n)
    return time.perf_counter() - t0


def warm_worker() -> int:
    import importlib

    for name in PRELOAD:
        importlib.import_module(name)
    time.sleep(0.2)  # hold this worker so the next warm-up task goes to another
    return os.getpid()


def study(executor: str, warm: int, refill: bool = True) -> Callable[[Path, list[Job]], float]:
    """The study through the sweep engine on ``--executor executor`` (``warm`` warm-up
    tasks first, so every worker has imported what a run needs; ``refill``: see
    :func:`~ffexp.sweeps.executors.make_executor`)."""
    def run(out: Path, jobs: list[Job]) -> float:
        jobs = [replace(j, out_dir=str(out)) for j in jobs]
        ex: Executor
        ex, slots = make_executor(parse_executor(executor), refill=refill)
        try:
            for f in [ex.submit(warm_worker) for _ in range(warm)]:
                f.result()
            t0 = time.perf_counter()
            with engine.Runner(out, ex, slots, lean=any(j.lean for j in jobs)) as r:
                rows = r.run_batch(jobs)
            wall = time.perf_counter() - t0
        finally:
            ex.shutdown(wait=True)
        bad = [row["error"] for row in rows if row["error"]]
        assert not bad, bad[0]
        return wall
    return run


def pool(workers: int) -> Callable[[Path, list[Job]], float]:
    """Today's pool: ``--executor local:N``."""
    return study(f"local:{workers}", 2 * workers)


def batched(processes: int, batch: int) -> Callable[[Path, list[Job]], float]:
    """The study through ``--executor local:P,batch:B`` (same engine, same rows)."""
    return study(f"local:{processes},batch:{batch}", 2 * processes)


def batch_profile(jobs: list[Job], tmp: Path) -> None:
    """One batch of the jobs in this process against the same runs one after the other:
    wall time, the physics dispatches' share, per run-cycle."""
    from drivers.world.gate import PhysicsGate
    from ffexp.sweeps.batch import run_batch
    from ffexp.sweeps.worker import run_one

    def moved(tag: str) -> list[Job]:
        return [replace(j, out_dir=str(tmp / tag)) for j in jobs]

    t0 = time.perf_counter()
    for j in moved("alone"):
        run_one(j)
    alone = time.perf_counter() - t0
    gate = PhysicsGate(1)
    t0 = time.perf_counter()
    out = run_batch(tuple(moved("batch")), gate=gate)
    wall = time.perf_counter() - t0
    assert all(kind == "row" and row["error"] is None for kind, row in out), out
    st = gate.stats
    print(f"one batch of {len(jobs)} runs in this process (one dispatch thread): "
          f"{wall:.2f} s, the runs one after the other {alone:.2f} s "
          f"(batch / alone {wall / alone:.2f}); {st.dispatches} dispatches of "
          f"{st.stepped / max(1, st.dispatches):.1f} runs on average")
    print(f"  per run-cycle: {wall / st.stepped * 1e6:.0f} us in all, of which the "
          f"physics dispatch {st.physics_s / st.stepped * 1e6:.0f} us "
          f"({st.physics_s / wall:.0%} of the batch's wall time; the rest is each run's "
          f"own Python, start-up and analysis included)")


def capture_cycles(tmp: Path, seconds: float = 3.0) -> list[list[tuple[str, bytes]]]:
    """A paper run's recorded cycles (Method I case I): per cycle its F/T samples'
    messages and then its topics', as the run log writes them."""
    import ffexp.experiment as experiment
    from ffexp.recording import Recorder

    cycles: list[list[tuple[str, bytes]]] = []
    pending: list[tuple[str, bytes]] = []

    class Capturing(Recorder):
        def write_series(self, topic: str, times_ns: list[int], datas: list[bytes]) -> None:
            pending.extend((topic, d) for d in datas)
            super().write_series(topic, times_ns, datas)

        def write_batch(self, time_ns: int, messages: list[tuple[str, bytes]]) -> None:
            cycles.append([*pending, *messages])
            pending.clear()
            super().write_batch(time_ns, messages)

    names = vars(experiment)  # the recorder run_file opens
    bare = names["Recorder"]
    names["Recorder"] = Capturing
    try:
        run_file(ROOT / "protocols/method1_case1.toml",
                 [f"run.timeout_s={seconds}", "run.stop_hold_s=0"], out_dir=tmp)
    finally:
        names["Recorder"] = bare
    return cycles


def recording_costs(runs: int, cycles: int, tmp: Path) -> None:
    """Per run and cycle: the fixed-layout topics encoded one run at a time (an encoder
    call per run and topic, as a run alone) against the batch's
    :class:`~ffexp.recording.batch.BatchEncoder` (an assignment per field for all the
    runs), and each run's cycle written to its own file (framing, chunks), all topics
    or a lean recording's. Thread CPU time; the runs' messages are a real run's."""
    from types import SimpleNamespace

    from ffexp.recording import Recorder
    from ffexp.recording.batch import BatchEncoder, lean_topic
    from ffexp.recording.topics import CDR_TOPICS

    recorded = capture_cycles(tmp / "capture")[-cycles:]
    per_cycle = recorded[-1]
    fixed = [(t, d) for t, d in per_cycle if t in CDR_TOPICS and t != "/ft/raw"]
    decoded = [(t, np.frombuffer(d, dtype=CDR_TOPICS[t].spec.dtype)[0]) for t, d in fixed]
    sources = [(t, SimpleNamespace(**{f.name: (rec[f.name].reshape(-1).copy() if f.count > 1
                                                else rec[f.name].item())
                                      for f in CDR_TOPICS[t].spec.fields}))
               for t, rec in decoded]
    clock = time.thread_time_ns
    with Recorder(tmp / "enc.mcap") as rec:
        t0 = clock()
        for _ in range(cycles):
            for _ in range(runs):
                for topic, src in sources:
                    rec.encode_fields(topic, src)
        alone_us = (clock() - t0) / 1e3 / (cycles * runs)
    arrays = [(topic, [(f.name, np.stack([np.asarray(getattr(src, f.name))] * runs))
                       for f in CDR_TOPICS[topic].spec.fields]) for topic, src in sources]
    encoders = {topic: BatchEncoder(topic, runs) for topic, _ in sources}
    t0 = clock()
    for _ in range(cycles):
        for topic, fields in arrays:
            enc = encoders[topic]
            for name, values in fields:
                enc.set(name, values)
            enc.messages()
    batch_us = (clock() - t0) / 1e3 / (cycles * runs)
    write_us = {}
    for lean in (False, True):
        recs = [Recorder(tmp / f"w{lean}{i}.mcap") for i in range(runs)]
        kept = [[(t, d) for t, d in c if not lean or lean_topic(t)] for c in recorded]
        t0 = clock()
        for k, msgs in enumerate(kept):
            for r in recs:
                r.write_batch(1_000_000_000 + 5_000_000 * k, msgs)
        write_us[lean] = (clock() - t0) / 1e3 / (len(kept) * runs)
        for r in recs:
            r.finish()
    n_full = len(per_cycle)
    n_lean = sum(lean_topic(t) for t, _ in per_cycle)
    print(f"recording per run and cycle ({runs} runs, {len(recorded)} cycles of a paper run; "
          f"thread CPU time):")
    print(f"  {len(sources)} fixed-layout topics encoded run by run   {alone_us:6.1f} us")
    print(f"  the same for the batch at once (BatchEncoder)  {batch_us:6.1f} us")
    print(f"  written to the run's file, {n_full} messages       {write_us[False]:6.1f} us")
    print(f"  written, lean ({n_lean} messages)                 {write_us[True]:6.1f} us")


def capture_estimator_inputs(tmp: Path, seconds: float = 4.0) -> list[tuple[Any, ...]]:
    """A paper run's estimator inputs (Method I case I), per cycle: the pose, the F/T
    samples, the link's commanding, ``t_ns`` and ``t0_ns``."""
    from ffexp.estimation import Estimator

    cycles: list[tuple[Any, ...]] = []
    bare = Estimator.update

    def update(self: Estimator, state: Any, ft: Any, t_ns: int, t0_ns: int) -> Any:
        cycles.append((state.tcp_pose_m.copy(), ft, state.link.commanding, t_ns, t0_ns))
        return bare(self, state, ft, t_ns, t0_ns)

    Estimator.update = update  # type: ignore[method-assign]
    try:
        run_file(ROOT / "protocols/method1_case1.toml",
                 [f"run.timeout_s={seconds}", "run.stop_hold_s=0"], out_dir=tmp)
    finally:
        Estimator.update = bare  # type: ignore[method-assign]
    return cycles


_COMPILE = """
import time
t0 = time.perf_counter()
import numba
t1 = time.perf_counter()
import numpy as np
from drivers.base.types import FtSamples, RobotState
from ffexp.estimation import Estimation, Estimator, ToolLoad
est = Estimator(Estimation(tool_load=ToolLoad(mass_kg=0.25)), 0.005, 0.1)
t2 = time.perf_counter()
ft = FtSamples(time_ns=np.arange(5, dtype=np.int64), seq=np.arange(5),
               wrench=np.zeros((5, 6)), status=np.zeros(5, dtype=np.uint32))
est.update(RobotState(), ft, 0, 0)
est.update(RobotState(), ft, 5_000_000, 0)
t3 = time.perf_counter()
print(t1 - t0, t3 - t2)
"""


def estimator_costs(runs: int, tmp: Path) -> None:
    """Per run and cycle: R runs' estimators stepped one by one against one estimator of
    the R runs; thread CPU time. Then import, compile and cache-load times."""
    import subprocess
    import sys

    from ffexp.estimation import Estimation, Estimator, ToolLoad

    recorded = capture_estimator_inputs(tmp / "capture")
    cycles = len(recorded)
    configs = [Estimation(tool_load=ToolLoad(mass_kg=0.2 + 0.01 * (i % 10))) for i in range(runs)]
    # run i follows the paper run from cycle (7 i) mod cycles on, wrapping round
    order: list[list[tuple[Any, ...]]] = [
        [recorded[(k + 7 * i) % cycles] for i in range(runs)] for k in range(cycles)]
    clock = time.thread_time_ns
    alone = [Estimator(c, 0.005, 0.1) for c in configs]
    states = [SimpleNamespace(tcp_pose_m=None, link=SimpleNamespace(commanding=True))
              for _ in range(runs)]
    t0 = clock()
    for row in order:
        for est, st, (pose, ft, commanding, t_ns, t0_ns) in zip(alone, states, row,
                                                                strict=True):
            st.tcp_pose_m = pose
            st.link.commanding = commanding
            est.update(st, ft, t_ns, t0_ns)  # type: ignore[arg-type]  # duck-typed state
    alone_us = (clock() - t0) / 1e3 / (cycles * runs)
    def pack(row: list[tuple[Any, ...]]) -> tuple[Any, ...]:
        fts = [r[1] for r in row]
        offsets = np.zeros(runs + 1, dtype=np.int64)
        np.cumsum([len(ft) for ft in fts], out=offsets[1:])
        return (np.stack([r[0] for r in row]), np.concatenate([ft.wrench for ft in fts]),
                np.concatenate([ft.time_ns for ft in fts]),
                np.concatenate([ft.status for ft in fts]), offsets,
                np.array([r[2] for r in row]), np.array([r[3] for r in row], dtype=np.int64),
                np.array([r[4] for r in row], dtype=np.int64))

    batch = Estimator(configs, 0.005, 0.1)
    t0 = clock()
    for row in order:
        batch.update_batch(*pack(row))
    batch_us = (clock() - t0) / 1e3 / (cycles * runs)
    packed = [pack(row) for row in order]
    batch = Estimator(configs, 0.005, 0.1)
    t0 = clock()
    for inputs in packed:
        batch.update_batch(*inputs)
    packed_us = (clock() - t0) / 1e3 / (cycles * runs)
    print(f"estimator per run and cycle ({runs} runs, {cycles} cycles of a paper run; "
          f"thread CPU time):")
    print(f"  each run alone (a batch of one each)         {alone_us:6.2f} us")
    print(f"  one estimator of the {runs} runs (update_batch)  {batch_us:6.2f} us")
    print(f"    of which the cycle, the inputs in arrays     {packed_us:6.2f} us")
    # a fresh process with an empty cache of its own (NUMBA_CACHE_DIR): it compiles and
    # writes the cache; the next one loads from it
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp / "numba-cache")}
    cold, warm = (subprocess.run([sys.executable, "-c", _COMPILE], capture_output=True,
                                 text=True, env=env, check=True, cwd=ROOT).stdout.split()
                  for _ in range(2))
    print(f"  import numba {float(warm[0]):.2f} s; the first cycle compiling "
          f"{float(cold[1]):.2f} s, loading the compiled code from the cache "
          f"{float(warm[1]):.2f} s")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=64)
    ap.add_argument("--seconds", type=float, default=8.0, help="run.timeout_s of each run")
    ap.add_argument("--workers", type=int, default=available_cpus())
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--batch", type=int, default=8, help="runs per batch of the batched study")
    ap.add_argument("--lean", action="store_true",
                    help="the study's runs record lean (as limits and reproduce do by default)")
    ap.add_argument("--recording", action="store_true",
                    help="only the recording's cost per run and cycle, alone and batched")
    ap.add_argument("--estimator", action="store_true",
                    help="only the estimator's cost per run and cycle, alone and batched")
    args = ap.parse_args()
    if args.estimator:
        with tempfile.TemporaryDirectory(prefix="bench_study_") as tmp_name:
            estimator_costs(args.runs, Path(tmp_name))
        return
    if args.recording:
        with tempfile.TemporaryDirectory(prefix="bench_study_") as tmp_name:
            recording_costs(args.runs, 400, Path(tmp_name))
        return
    warm_worker()
    load0 = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="bench_study_") as tmp_name:
        tmp = Path(tmp_name)
        jobs = make_jobs(tmp / "jobs", args.runs, args.seconds, args.lean)
        t0 = time.perf_counter()
        caps = capture_runs(jobs, tmp)
        print(f"captured {len(caps)} runs' physics in {time.perf_counter() - t0:.1f} s "
              f"(one process, not counted)")
        sim_s = sum(c.sim_s for c in caps)
        steps = sum(c.steps for c in caps)
        run_pool = pool(args.workers)
        run_study = batched(args.workers, args.batch)
        times: dict[str, list[float]] = {"pool": [], "study": [], "batched": [], "loop": []}
        for k in range(args.repeats):
            times["pool"].append(run_pool(tmp / f"pool{k}", jobs))
            times["study"].append(run_study(tmp / f"study{k}", jobs))
            times["batched"].append(replay_batched(caps, args.workers))
            times["loop"].append(replay_loop(caps))
        batch_profile(jobs[:args.batch], tmp / "profile")
    load1 = os.getloadavg()
    rate = {name: sim_s / statistics.median(t) for name, t in times.items()}
    print(f"{args.runs} runs ({', '.join(PROTOCOLS)}), timeout {args.seconds:g} s: "
          f"{sim_s:.1f} s simulated, {steps} steps; recordings "
          f"{'lean' if args.lean else 'full'}; {args.repeats} repeats, medians; "
          f"{available_cpus()} CPUs, {args.workers} workers / threads")
    labels = {"pool": f"today's pool (local:{args.workers})",
              "study": f"batched study (local:{args.workers},batch:{args.batch})",
              "batched": f"bare batched physics ({args.workers} threads)",
              "loop": "bare physics, one thread"}
    print(f"{'path':40s} {'wall [s]':>9s} {'sim s / wall s':>15s} {'of batched':>11s} "
          f"{'of pool':>8s}")
    for name, label in labels.items():
        print(f"{label:40s} {statistics.median(times[name]):9.2f} {rate[name]:15.2f} "
              f"{rate[name] / rate['batched']:11.2f} {rate[name] / rate['pool']:8.2f}")
    print(f"replay vs recorded runs: largest |qpos| difference at a run's end "
          f"{max(REPLAY_DRIFT):.3g}")
    print("load average (1, 5, 15 min): before " + ", ".join(f"{x:.2f}" for x in load0)
          + "; after " + ", ".join(f"{x:.2f}" for x in load1))


if __name__ == "__main__":
    main()
