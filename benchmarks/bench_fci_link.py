"""libfranka's link in real time: ``ffexp emulate --robot fr3`` at 1 kHz over loopback, driven by
Franka's own client ``pylibfranka`` (the test extra), each in a process of its own.

Run (10 s of reading and 10 s of torque loop, as the acceptance of the Franka back-end
asks)::

    python benchmarks/bench_fci_link.py --seconds 10 --rt on --pin

Options: ``--rt off|on`` (the emulator with ``--rt``: SCHED_FIFO where the OS allows it,
the collector frozen); ``--pin`` (the emulator on CPU 0, the client on CPU 1).

The client reads the state for ``--seconds`` (no commands), then runs libfranka's torque
loop (``start_torque_control``, ``readOnce``/``writeOnce``) for as long: zero torque,
then a 0.2 N m step on joint 1 for its last 5 % (at 10 s about 0.1 rad: a longer step runs
the joint into its speed limits, a reflex). Printed, as JSON: per phase the
states read, the cycles missed as the client counts them (the state's time advancing
more than 1 ms from one read to the next: the sum of the excess), their share, the
period between reads (p50, p99, p99.9, max) and, in the loop, the time from a state's
read to its torques written; the robot's ``control_command_success_rate`` at the end;
and the emulator's counters (answered, missed and late commands as it counts them).
Nothing here is asserted: these are measurements of this machine, as it is loaded.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CLIENT = r"""
import json, os, sys, time
import pylibfranka as plf
host, seconds, cpu = sys.argv[1], float(sys.argv[2]), int(sys.argv[3])
if cpu >= 0:
    os.sched_setaffinity(0, {cpu})
def summary(ids, stamps, work=None):
    import numpy as np
    gaps = np.diff(np.array(ids))
    missed = int(np.sum(np.maximum(gaps - 1, 0)))
    per = np.diff(np.array(stamps)) * 1e3
    out = {"reads": len(ids), "missed": missed,
           "missed_pct": round(100.0 * missed / max(1, missed + len(ids)), 3),
           "period_ms": {k: round(float(np.percentile(per, q)), 3) for k, q in
                         (("p50", 50), ("p99", 99), ("p99.9", 99.9), ("max", 100))}}
    if work:
        w = np.array(work) * 1e3
        out["read_to_write_ms"] = {k: round(float(np.percentile(w, q)), 4) for k, q in
                                   (("p50", 50), ("p99", 99), ("p99.9", 99.9), ("max", 100))}
    return out
r = plf.Robot(host, plf.RealtimeConfig.kIgnore)
ids, stamps = [], []
end = time.perf_counter() + seconds
while time.perf_counter() < end:
    s = r.read_once()
    stamps.append(time.perf_counter()); ids.append(round(s.time.to_sec() * 1000))
read = summary(ids, stamps)
ctrl = r.start_torque_control()
ids, stamps, work = [], [], []
t0 = time.perf_counter()
end = t0 + seconds
q0 = None
while True:
    st, _ = ctrl.readOnce()
    now = time.perf_counter()
    if q0 is None:
        q0 = st.q[0]
    stamps.append(now); ids.append(round(st.time.to_sec() * 1000))
    step = 0.2 if now > t0 + 0.95 * seconds else 0.0
    ctrl.writeOnce(plf.Torques([step, 0, 0, 0, 0, 0, 0]))
    work.append(time.perf_counter() - now)
    if now >= end:
        break
loop = summary(ids, stamps, work)
loop["success_rate"] = st.control_command_success_rate
loop["joint1_moved_rad"] = st.q[0] - q0
r.stop()
print(json.dumps({"read": read, "torque_loop": loop}))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--rt", choices=("off", "on"), default="on")
    ap.add_argument("--pin", action="store_true")
    ap.add_argument("--host", default="127.0.0.61")
    args = ap.parse_args()
    emu_cmd = [sys.executable, "-c", "from ffexp.cli import main; main()", "emulate",
               "--robot", "fr3", "--listen", f"{args.host}:1337"]
    if args.rt == "on":
        emu_cmd += ["--rt", *(("--cpu", "0") if args.pin else ())]
    emu = subprocess.Popen(emu_cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                           text=True, cwd=ROOT)
    assert emu.stdout is not None
    while "FR3 (libfranka protocol" not in (line := emu.stdout.readline()):
        if not line:
            sys.exit(f"the emulator did not start: {line!r}")
    time.sleep(0.2)
    res = subprocess.run([sys.executable, "-c", CLIENT, args.host, str(args.seconds),
                          "1" if args.pin else "-1"], capture_output=True, text=True)
    emu.terminate()
    out, _ = emu.communicate(timeout=30)
    if res.returncode != 0:
        sys.exit(res.stderr)
    result = json.loads(res.stdout)
    result["emulator"] = next((ln.split("cycles; ", 1)[-1] for ln in out.splitlines()
                               if "FR3 over libfranka" in ln), "")
    result["cpus"] = os.cpu_count()
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
