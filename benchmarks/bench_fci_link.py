"""libfranka's link in real time: ``ffexp emulate --robot fr3`` at 1 kHz over loopback, driven by
Franka's own client ``pylibfranka`` (the test extra), each in a process of its own.

Run (10 s of reading and 10 s of torque loop, as the acceptance of the Franka back-end
asks; ``--runs 4`` repeats it)::

    python benchmarks/bench_fci_link.py --seconds 10 --rt on --pin

Options: ``--rt off|on`` (the emulator with ``--rt``: SCHED_FIFO where the OS allows it,
the collector frozen and disabled; the client the same, its collector off during its
loops: ``--client-rt off`` leaves the client at normal priority with its collector on);
``--pin`` (the emulator on CPU 0, the client on CPU 1).

The client reads the state for ``--seconds`` (no commands), then runs libfranka's torque
loop (``start_torque_control``, ``readOnce``/``writeOnce``) for as long: zero torque,
then a 0.2 N m step on joint 1 for its last 5 % (at 10 s about 0.1 rad: a longer step
runs the joint into its speed limits, a reflex). Printed, as JSON, per run: the load
average (1 min) before and after; per phase the states read, the cycles missed as the
client counts them (the state's time advancing more than 1 ms from one read to the next:
the sum of the excess), their share, how many of them fell in stalls
(``missed_in_stalls``: reads more than ``--stall-ms``, default 5, apart: at least five
cycles in which the client read nothing), the period between reads (p50, p99, p99.9,
max: the worst stall), how far the robot's clock fell behind the wall's
(``clock_lag_pct``: the state's time advanced that much less than the wall clock, from
cycles the emulator began more than a cycle late, which the client cannot count as
missed) and, in the loop, the time from a state's read to its torques written; the
robot's ``control_command_success_rate`` at the end; the emulator's counters (answered,
missed and late commands and overruns as it counts them), its serving thread's CPU time
per cycle (``cycle_cpu_us``: p50, p99, max) and its page faults while the client ran;
the time a hypervisor took each CPU meanwhile (``steal_ms_per_cpu``: a stall no setting
in the guest prevents); and what ``--rt`` obtained on either side.
Nothing here is asserted: these are measurements of this machine, as it is loaded.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CLIENT = r"""
import gc, json, os, sys, time
import pylibfranka as plf
host, seconds, cpu, rt = sys.argv[1], float(sys.argv[2]), int(sys.argv[3]), sys.argv[4] == "1"
STALL_MS = float(sys.argv[5])
got = []
if cpu >= 0:
    os.sched_setaffinity(0, {cpu})
    got.append(f"pinned to CPU {cpu}")
if rt:
    try:  # libfranka's own kEnforce wants a real-time kernel: set the policy here
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(40))
        got.append("SCHED_FIFO priority 40")
    except PermissionError:
        got.append("SCHED_FIFO refused: normal priority")
    got.append("garbage collection off in the loops")
def summary(ids, stamps, work=None):
    import numpy as np
    ids, stamps = np.array(ids), np.array(stamps)
    gaps = np.diff(ids)
    missed = int(np.sum(np.maximum(gaps - 1, 0)))
    per = np.diff(stamps) * 1e3
    wall_ms = (stamps[-1] - stamps[0]) * 1e3
    out = {"reads": len(ids), "missed": missed,
           "missed_pct": round(100.0 * missed / max(1, missed + len(ids)), 3),
           "period_ms": {k: round(float(np.percentile(per, q)), 3) for k, q in
                         (("p50", 50), ("p99", 99), ("p99.9", 99.9), ("max", 100))},
           "clock_lag_pct": round(100.0 * (1.0 - (ids[-1] - ids[0]) / wall_ms), 2)}
    stalled = per > STALL_MS
    out["missed_in_stalls"] = int(np.sum(np.maximum(gaps - 1, 0)[stalled]))
    out["stalls"] = int(np.sum(stalled))
    if work:
        w = np.array(work) * 1e3
        out["read_to_write_ms"] = {k: round(float(np.percentile(w, q)), 4) for k, q in
                                   (("p50", 50), ("p99", 99), ("p99.9", 99.9), ("max", 100))}
    return out
r = plf.Robot(host, plf.RealtimeConfig.kIgnore)
clock = time.perf_counter
ids, stamps = [], []
if rt:
    gc.collect(); gc.freeze(); gc.disable()
end = clock() + seconds
while True:
    s = r.read_once()
    now = clock()
    stamps.append(now); ids.append(round(s.time.to_sec() * 1000))
    if now >= end:
        break
read = summary(ids, stamps)
ctrl = r.start_torque_control()
zero = plf.Torques([0.0] * 7)
step = plf.Torques([0.2, 0, 0, 0, 0, 0, 0])
ids, stamps, work = [], [], []
if rt:
    gc.collect(); gc.freeze()
t0 = clock()
end = t0 + seconds
t_step = t0 + 0.95 * seconds
q0 = None
while True:
    st, _ = ctrl.readOnce()
    now = clock()
    ctrl.writeOnce(step if now > t_step else zero)
    work.append(clock() - now)
    stamps.append(now); ids.append(round(st.time.to_sec() * 1000))
    if q0 is None:
        q0 = st.q[0]
    if now >= end:
        break
gc.enable()
loop = summary(ids, stamps, work)
loop["success_rate"] = st.control_command_success_rate
loop["joint1_moved_rad"] = st.q[0] - q0
r.stop()
print(json.dumps({"read": read, "torque_loop": loop, "client_rt": "; ".join(got)}))
"""


def faults(pid: int) -> tuple[int, int]:
    """A process's minor and major page faults so far (0, 0 where /proc has none)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0, 0
    return int(fields[7]), int(fields[9])


def steal_ticks() -> list[int]:
    """Per CPU, the time the hypervisor ran something else on it (``steal`` in /proc/stat,
    in clock ticks; empty where there is none)."""
    try:
        lines = Path("/proc/stat").read_text().splitlines()
    except OSError:
        return []
    return [int(ln.split()[8]) for ln in lines if ln.startswith("cpu") and ln[3].isdigit()]


def load1() -> float:
    return float(Path("/proc/loadavg").read_text().split()[0]) if Path(
        "/proc/loadavg").exists() else float("nan")


def one_run(args: argparse.Namespace) -> dict[str, object]:
    emu_cmd = [sys.executable, "-c", "from ffexp.cli import main; main()", "emulate",
               "--robot", "fr3", "--listen", f"{args.host}:1337"]
    if args.rt == "on":
        emu_cmd += ["--rt", *(("--cpu", "0") if args.pin else ())]
    load_before = load1()
    emu = subprocess.Popen(emu_cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                           text=True, cwd=ROOT)
    assert emu.stdout is not None
    emu_rt = ""
    while "FR3 (libfranka protocol" not in (line := emu.stdout.readline()):
        if not line:
            sys.exit(f"the emulator did not start: {line!r}")
        if "--rt:" in line:
            emu_rt = line.split("--rt:", 1)[1].strip()
    time.sleep(0.2)
    faults0 = faults(emu.pid)
    steal0 = steal_ticks()
    client_rt = args.rt == "on" and args.client_rt == "on"
    res = subprocess.run([sys.executable, "-c", CLIENT, args.host, str(args.seconds),
                          "1" if args.pin else "-1", "1" if client_rt else "0",
                          str(args.stall_ms)],
                         capture_output=True, text=True)
    faults1 = faults(emu.pid)
    steal1 = steal_ticks()
    emu.terminate()
    out, _ = emu.communicate(timeout=30)
    if res.returncode != 0:
        sys.exit(res.stderr)
    result: dict[str, object] = {"load1_before": load_before, "load1_after": load1()}
    result.update(json.loads(res.stdout))
    counters = next((ln.split("cycles; ", 1)[-1] for ln in out.splitlines()
                     if "FR3 over libfranka" in ln), "")
    result["emulator"] = re.sub(r" cycle_cpu_us_.*", "", counters)
    result["emulator_cycle_cpu_us"] = {m[0]: float(m[1]) for m in re.findall(
        r"cycle_cpu_us_(\w+) ([\d.]+)", counters)}
    result["emulator_rt"] = emu_rt
    tick_ms = 1000.0 / os.sysconf("SC_CLK_TCK")
    result["steal_ms_per_cpu"] = [round((b - a) * tick_ms)
                                  for a, b in zip(steal0, steal1, strict=True)]
    result["emulator_page_faults"] = {"minor": faults1[0] - faults0[0],
                                      "major": faults1[1] - faults0[1]}
    return result


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--rt", choices=("off", "on"), default="on")
    ap.add_argument("--client-rt", choices=("off", "on"), default="on")
    ap.add_argument("--pin", action="store_true")
    ap.add_argument("--runs", type=int, default=1)
    ap.add_argument("--host", default="127.0.0.61")
    ap.add_argument("--stall-ms", type=float, default=5.0)
    args = ap.parse_args()
    runs = []
    for _ in range(args.runs):
        runs.append(one_run(args))
        print(json.dumps(runs[-1], indent=2), flush=True)
    if args.runs > 1:
        print(json.dumps({"cpus": os.cpu_count(), "runs": [
            {"load1": r["load1_before"], **{ph: {k: r[ph][k] for k in  # type: ignore[index]
             ("missed_pct", "missed_in_stalls", "clock_lag_pct")}
             | {"max_ms": r[ph]["period_ms"]["max"]}  # type: ignore[index]
             for ph in ("read", "torque_loop")},
             "cycle_cpu_us": r["emulator_cycle_cpu_us"],
             "steal_ms_per_cpu": r["steal_ms_per_cpu"]} for r in runs]}, indent=1))


if __name__ == "__main__":
    main()
