"""The simulated UR5e: a campaign in-process and over RTDE in lockstep, against its own physics.

    .venv/bin/python benchmarks/bench_ur_sim.py [--campaign protocols/paper.toml] [--no-truth-run]

Runs the campaign (default: the paper's five runs) in this process with
``ffexp.campaign.run_campaign``, three ways, each timed as a whole (wall time
from the first run's start to the last run's end; the interpreter's start is
not in it):

* **in-process**: ``rigs/ur5e-sim.toml`` with ``robot.truth=false``, so the
  observer judges as it must over RTDE (no ground truth crosses the wire);
* **over RTDE**: ``rigs/ur5e-emulator.toml`` against one ``ffexp emulate
  --robot ur5e --pacing lockstep`` (a process of its own on a free
  127.0.0.x:30004, the campaign's seed), which starts each run's session
  anew;
* **in-process, judged by the truth** (the rig's default, what ``ffexp
  campaign PAPER --rig rigs/ur5e-sim.toml`` does): runs end once aligned.

The baseline is **bare physics**: the wall time of every ``mujoco.mj_step``
call the in-process runs made (``bench_runner.timed_physics``: the same model,
states and steps; the RTDE runs step the same states, their recordings being
equal). Prints each path's simulated seconds, wall seconds, real-time factor
and its ratio to the bare physics, and whether the two observer-judged paths
ended every run the same way (end, alignment, breaks, cycles).
"""

from __future__ import annotations

import argparse
import os
import socket
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from bench_runner import timed_physics

from ffexp.campaign import check_campaign, run_campaign
from ffexp.experiment import RunResult
from ffexp.protocol import load_run_protocol
from ffexp.rig_choice import RigChoice

ROOT = Path(__file__).resolve().parents[1]
PY = sys.executable
ENV = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}


@dataclass
class Way:
    """One way of running the campaign, measured."""

    name: str
    sim_s: float
    wall_s: float
    physics_s: float | None
    runs: list[RunResult]

    @property
    def factor(self) -> float:
        return self.sim_s / self.wall_s


def campaign(name: str, camp: Path, rig: RigChoice, out: Path, *, physics: bool) -> Way:
    """Run ``camp`` on ``rig``; with ``physics``, also the time of its ``mj_step`` calls."""
    start = time.perf_counter()
    if physics:
        with timed_physics() as total:
            result = run_campaign(camp, rig=rig, out_parent=out)
        spent: float | None = total[0]
    else:
        result = run_campaign(camp, rig=rig, out_parent=out)
        spent = None
    wall = time.perf_counter() - start
    sim = sum(r.outcome.duration_s for r in result.results)
    return Way(name, sim, wall, spent, list(result.results))


def free_host() -> str:
    """A loopback address whose port 30004 is free."""
    for i in range(40, 240):
        host = f"127.0.0.{i}"
        s = socket.socket()
        try:
            s.bind((host, 30004))
            return host
        except OSError:
            continue
        finally:
            s.close()
    raise SystemExit("no loopback address with a free port 30004")


def end(r: RunResult) -> tuple[str, bool, int, int]:
    o = r.outcome
    return o.stop_reason.value, o.aligned, o.breaks, o.cycles


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--campaign", type=Path, default=ROOT / "protocols/paper.toml")
    parser.add_argument("--no-truth-run", action="store_true",
                        help="skip the in-process campaign judged by the ground truth")
    args = parser.parse_args()
    sim_rig = ROOT / "rigs/ur5e-sim.toml"
    _, entries = check_campaign(args.campaign, (), RigChoice(sim_rig))
    seeds = {load_run_protocol(e.protocol, e.overrides).seed for e in entries}
    if len(seeds) != 1:
        raise SystemExit(f"{args.campaign}: its runs have seeds {sorted(seeds)}; one emulator "
                         "serves one seed")
    (seed,) = seeds
    paths: list[Way] = []
    with tempfile.TemporaryDirectory() as tmp:
        paths.append(campaign("in-process", args.campaign,
                              RigChoice(sim_rig, ("robot.truth=false",)), Path(tmp),
                              physics=True))
        host = free_host()
        emu = subprocess.Popen([PY, "-m", "ffexp", "emulate", "--robot", "ur5e", "--listen",
                                f"{host}:30004", "--pacing", "lockstep", "--seed", str(seed)],
                               cwd=ROOT, env=ENV, stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE, text=True)
        try:
            assert emu.stderr is not None
            while "UR5e controller" not in emu.stderr.readline():
                if emu.poll() is not None:
                    raise SystemExit("the emulator ended before it served")
            paths.append(campaign("over RTDE, lockstep", args.campaign,
                                  RigChoice(ROOT / "rigs/ur5e-emulator.toml",
                                            (f"robot.robot_ip={host}",)),
                                  Path(tmp), physics=False))
        finally:
            emu.terminate()
            emu.wait(30)
        if not args.no_truth_run:
            paths.append(campaign("in-process, truth judges", args.campaign, RigChoice(sim_rig),
                                  Path(tmp), physics=True))
    observer, wire = paths[0], paths[1]
    assert observer.physics_s is not None
    bare = observer.sim_s / observer.physics_s
    print(f"{args.campaign.name}: {len(observer.runs)} runs, seed {seed}")
    print(f"  observer judges: {observer.sim_s:.1f} s simulated; bare physics "
          f"{observer.physics_s:.1f} s = {bare:.2f}x real time")
    for p in paths[:2]:
        print(f"    {p.name:24s} {p.wall_s:7.1f} s  {p.factor:5.2f}x real time, "
              f"{p.factor / bare:.2f} of the bare physics")
    same = [end(a) == end(b) for a, b in zip(observer.runs, wire.runs, strict=True)]
    print(f"    the same ends (end, aligned, breaks, cycles): {sum(same)} of {len(same)} runs")
    for a, b, ok in zip(observer.runs, wire.runs, same, strict=True):
        print(f"      {a.protocol.name:20s} {end(a)}  {'=' if ok else '!='}  {end(b)}")
    if len(paths) > 2:
        t = paths[2]
        assert t.physics_s is not None
        tb = t.sim_s / t.physics_s
        print(f"  truth judges (in-process): {t.sim_s:.1f} s simulated; bare physics "
              f"{t.physics_s:.1f} s = {tb:.2f}x real time")
        print(f"    {t.name:24s} {t.wall_s:7.1f} s  {t.factor:5.2f}x real time, "
              f"{t.factor / tb:.2f} of the bare physics")


if __name__ == "__main__":
    main()
