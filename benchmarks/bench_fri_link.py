"""The FRI link in real time: the remote driver against ``ffexp emulate``, 1 ms and 5 ms.

Run (the figures in benchmarks/README.md: 60 s per configuration, on a quiet machine)::

    python benchmarks/bench_fri_link.py --seconds 60

Options: ``--cycle-ms 1,5`` (the FRI cycles measured), ``--rt both|off|on``
(without and/or with ``--rt``: SCHED_FIFO where the OS allows it, garbage
collection frozen and disabled, for this process and the emulator's),
``--pin`` (with ``--rt``: the emulator on CPU 0, this process on CPU 1),
``--mode runner|immediate`` (the driver's answer policy: the runner's command
of the cycle with a deadline of half a cycle, or the latest command on arrival).

The emulator runs as its own process (as a KRC is its own machine), in
real-time pacing on loopback; this process runs :class:`FriRobot` and a minimal
runner that answers every measurement with a constant command. After the link
first reaches CMD and settles (``--warmup-s``), per configuration over
``--seconds``:

- the driver's turnaround (packet received -> answer sent): p50, p99, p99.9, max;
- missed cycles: the KRC's own miss counter (no answer in time), and its share;
- time in CMD: the share of measured cycles the KRC reported state CMD;
- the KRC's quality histogram (shares of PERFECT, OK, BAD, UNACCEPTABLE);
  (a link that has not reached CMD after 5 s is measured as it is);
- measurements lost on the way in, runner answers late (deadline repeats), and
  the emulator's own overruns (cycles it started more than a cycle late).

Nothing here is asserted: these are measurements of this machine, as it is loaded.
"""

from __future__ import annotations

import argparse
import re
import shutil
import signal
import subprocess
import sys
import time
from collections import Counter
from contextlib import nullcontext
from pathlib import Path

import numpy as np

from drivers.base.types import CartesianCommand
from drivers.fri.backend import FriRobotConfig
from drivers.fri.driver import FriRobot
from drivers.fri.types import FriMeasurement, FriQuality, FriState
from ffexp.rt import realtime


def ffexp_exe() -> str:
    return shutil.which("ffexp") or str(Path(sys.executable).parent / "ffexp")


def bench(cycle_ms: int, seconds: float, rt: bool, mode: str, warmup_s: float,
          pin: bool = False) -> dict[str, object]:
    deadline = 0.0 if mode == "immediate" else 0.5
    robot = FriRobot(FriRobotConfig(robot_ip="127.0.0.1", port=0, bind_host="127.0.0.1",
                                    answer_deadline_cycles=deadline, connect_timeout_s=30.0,
                                    cycle_timeout_s=5.0))
    _, port = robot.bind()
    n = round(seconds * 1000 / cycle_ms)
    settle = round(warmup_s * 1000 / cycle_ms)
    limit_s = 2 * (seconds + warmup_s) + 30.0
    emu = subprocess.Popen(
        [ffexp_exe(), "emulate", "--remote", f"127.0.0.1:{port}", "--cycle-ms", str(cycle_ms),
         "--pacing", "realtime", "--netft-port", "-1", "--duration", str(limit_s),
         *(["--rt"] if rt else []), *(["--cpu", "0"] if rt and pin else [])],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )
    cmd = CartesianCommand(stiffness_npm_nmprad=np.full(6, 1000.0),
                           damping_ratio=np.full(6, 0.7))
    states: Counter[str] = Counter()
    qualities: Counter[str] = Counter()
    got_rt = ""
    t0 = wall = 0.0
    try:
        with realtime((1,) if pin else ()) if rt else nullcontext() as report:
            got_rt = str(report) if report is not None else "off"
            robot.connect()
            k = settled = waited = 0
            give_up = round(5.0 * 1000 / cycle_ms)  # a link that never reaches CMD: measure it
            start_turn = start_miss = start_lost = start_late = 0
            first = True
            for state in robot.measurements():
                m = state.extras
                assert isinstance(m, FriMeasurement)
                if first:
                    cmd.pose_m[:] = state.tcp_pose_m
                    first = False
                robot.send(cmd)
                waited += 1
                if settled == 0:  # wait for CMD (or give up on it), then let the link settle
                    k = k + 1 if (k or m.state == FriState.CMD or waited > give_up) else 0
                    if k >= settle:
                        settled = 1
                        st = robot.stats
                        start_turn = robot.turnarounds_ns().shape[0]
                        start_miss, start_lost = m.miss_counter, st.lost
                        start_late = st.deadline_answers
                        t0 = time.perf_counter()
                    continue
                states[m.state.name] += 1
                qualities[m.quality.name] += 1
                settled += 1
                if settled > n:
                    break
            wall = time.perf_counter() - t0
            st = robot.stats
            turn = robot.turnarounds_ns()[start_turn:] * 1e-3  # us
    finally:
        robot.close()
        emu.send_signal(signal.SIGTERM)
        try:
            _, err = emu.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            emu.kill()
            _, err = emu.communicate()
    summary = next((line for line in reversed(err.splitlines()) if "cycles" in line), "")
    overruns = re.search(r"overruns (\d+)", summary)
    late_sends = re.search(r"late sends (\d+) \(latest ([\d.]+) ms, misses after one (\d+)",
                           summary)
    emu_rt = next((line for line in err.splitlines() if "--rt" in line or "SCHED" in line), "")
    seen = sum(states.values())
    missed = st.miss_counter - start_miss
    return {
        "cycle_ms": cycle_ms, "rt": rt, "rt_report": got_rt, "emu_rt": emu_rt.strip(),
        "cycles": seen, "wall_s": wall,
        "turn": [float(np.percentile(turn, q)) for q in (50, 99, 99.9)] + [float(turn.max())],
        "missed": missed, "missed_share": missed / max(seen, 1),
        "cmd_share": states.get(FriState.CMD.name, 0) / max(seen, 1),
        "quality": {q.name: qualities.get(q.name, 0) / max(seen, 1)
                    for q in (FriQuality.PERFECT, FriQuality.OK, FriQuality.BAD,
                              FriQuality.UNACCEPTABLE)},
        "lost": st.lost - start_lost, "late": st.deadline_answers - start_late,
        "overruns": int(overruns.group(1)) if overruns else -1,
        "late_sends": late_sends.groups() if late_sends else ("?", "?", "?"),
    }


def show(r: dict[str, object]) -> None:
    p50, p99, p999, mx = r["turn"]  # type: ignore[misc]
    q = " ".join(f"{k} {v:.1%}" for k, v in r["quality"].items())  # type: ignore[attr-defined]
    print(f"{r['cycle_ms']} ms, --rt {'on ' if r['rt'] else 'off'}: {r['cycles']} cycles in "
          f"{r['wall_s']:.1f} s | turnaround p50 {p50:.0f} us, p99 {p99:.0f} us, p99.9 "
          f"{p999:.0f} us, max {mx:.0f} us | missed {r['missed']} ({r['missed_share']:.2%}) | "
          f"in CMD {r['cmd_share']:.1%} | quality {q} | lost {r['lost']}, runner late "
          f"{r['late']}, emulator overruns {r['overruns']}, emulator late sends "
          f"{r['late_sends'][0]} (latest {r['late_sends'][1]} ms, misses after one "  # type: ignore[index]
          f"{r['late_sends'][2]})")  # type: ignore[index]
    if r["rt"]:
        print(f"    this process: {r['rt_report']}")
        if r["emu_rt"]:
            print(f"    emulator: {r['emu_rt']}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0,
                    help="measured time per configuration (benchmarks/README.md figures: 60)")
    ap.add_argument("--cycle-ms", default="1,5", help="FRI cycles to measure, comma-separated")
    ap.add_argument("--rt", choices=("both", "off", "on"), default="both")
    ap.add_argument("--mode", choices=("runner", "immediate"), default="runner")
    ap.add_argument("--warmup-s", type=float, default=1.0,
                    help="time after the first CMD before measuring")
    ap.add_argument("--pin", action="store_true",
                    help="with --rt: the emulator on CPU 0, this process on CPU 1")
    args = ap.parse_args()
    cycles = [int(c) for c in args.cycle_ms.split(",")]
    rts = {"both": (False, True), "off": (False,), "on": (True,)}[args.rt]
    print(f"FRI link against ffexp emulate in real time (own process), loopback, answer mode "
          f"{args.mode}, {args.seconds:g} s per configuration")
    for cycle_ms in cycles:
        for rt in rts:
            show(bench(cycle_ms, args.seconds, rt, args.mode, args.warmup_s, args.pin))


if __name__ == "__main__":
    main()
