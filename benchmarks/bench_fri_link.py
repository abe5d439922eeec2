"""Round-trip turnaround of the FRI remote driver at 1 kHz against ``ffexp emulate`` in real time.

Run: ``python benchmarks/bench_fri_link.py [--seconds 10] [--cycle-ms 1] [--mode both]``

The emulator runs as its own process (as a KRC would be its own machine),
in real-time pacing on loopback; this process runs :class:`FriRobot` and a
minimal runner loop that answers every measurement with a constant command.
Two answer modes are measured:

* ``runner``: the driver answers when the runner has sent its command for
  the cycle (the default; deadline half a cycle);
* ``immediate``: the I/O thread answers on arrival with the latest command.

Printed per mode, over the measured cycles (after the link reached CMD):
the driver's turnaround (packet received -> answer sent) p50/p99/p99.9/max,
the KRC-side latency (packet sent -> answer received, as the emulator
reports it), missed cycles (the emulator's miss counter), measurements lost
on the way in, and answers the runner missed (deadline answers).
"""

from __future__ import annotations

import argparse
import shutil
import signal
import subprocess
import sys
import time

import numpy as np

from drivers.base.types import CartesianCommand
from drivers.fri.driver import FriRobot, FriSettings
from drivers.fri.types import FriMeasurement


def ffexp_exe() -> str:
    path = shutil.which("ffexp") or str(__import__("pathlib").Path(sys.executable).parent / "ffexp")
    return path


def bench(mode: str, seconds: float, cycle_ms: int) -> dict[str, float]:
    deadline = 0.0 if mode == "immediate" else 0.5
    robot = FriRobot(FriSettings(robot_ip="127.0.0.1", local_port=0, local_host="127.0.0.1",
                                 answer_deadline_cycles=deadline, connect_timeout_s=30.0))
    _, port = robot.bind()
    warmup = 500  # the link settles (friStart needs 100 answered cycles at PERFECT quality)
    n = int(seconds * 1000 / cycle_ms)
    emu = subprocess.Popen(
        [ffexp_exe(), "emulate", "--remote", f"127.0.0.1:{port}", "--cycle-ms", str(cycle_ms),
         "--pacing", "realtime", "--netft-port", "-1",
         "--duration", str((warmup + n) * cycle_ms / 1000 + 5.0)],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )
    # hold the first measured pose with a constant impedance (set on the first cycle)
    cmd = CartesianCommand(stiffness_npm_nmprad=np.full(6, 1000.0),
                           damping_ratio=np.full(6, 0.7))
    lat: list[float] = []
    states: dict[str, int] = {}
    qualities: dict[str, int] = {}
    try:
        robot.connect()
        k = 0
        start_turn = start_miss = start_lost = start_deadline = 0
        for state in robot.measurements():
            m = state.extras
            assert isinstance(m, FriMeasurement)
            if k == 0:
                cmd.pose_m[:] = state.tcp_pose_m
            robot.send(cmd)
            k += 1
            if k == warmup:
                st = robot.stats
                start_turn = robot.turnarounds_ns().shape[0]
                start_miss, start_lost = m.miss_counter, st.lost
                start_deadline = st.deadline_answers
                t0 = time.perf_counter()
            elif k > warmup:
                lat.append(m.latency_s)
                states[m.state.name] = states.get(m.state.name, 0) + 1
                qualities[m.quality.name] = qualities.get(m.quality.name, 0) + 1
                if k >= warmup + n:
                    break
        wall = time.perf_counter() - t0
        st = robot.stats
        turn = robot.turnarounds_ns()[start_turn:] * 1e-3  # us
        end_miss = st.miss_counter  # the KRC's counter of the last measurement
    finally:
        robot.close()
        emu.send_signal(signal.SIGTERM)
        try:
            _, err = emu.communicate(timeout=20)
        except subprocess.TimeoutExpired:
            emu.kill()
            _, err = emu.communicate()
    summary = [line for line in err.splitlines() if "cycles" in line]
    la = np.array(lat) * 1e6
    return {
        "cycles": float(n),
        "wall_s": wall,
        "turn_p50": float(np.percentile(turn, 50)),
        "turn_p99": float(np.percentile(turn, 99)),
        "turn_p999": float(np.percentile(turn, 99.9)),
        "turn_max": float(turn.max()),
        "krc_lat_p50": float(np.percentile(la, 50)),
        "krc_lat_p99": float(np.percentile(la, 99)),
        "missed": float(end_miss - start_miss),
        "lost_in": float(st.lost - start_lost),
        "deadline": float(st.deadline_answers - start_deadline),
        "summary": summary[-1] if summary else "",  # type: ignore[dict-item]
        "states": states,  # type: ignore[dict-item]
        "qualities": qualities,  # type: ignore[dict-item]
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=10.0, help="measured time per mode")
    ap.add_argument("--cycle-ms", type=int, default=1, help="FRI cycle (friOpen)")
    ap.add_argument("--mode", choices=("runner", "immediate", "both"), default="both")
    args = ap.parse_args()
    modes = ("runner", "immediate") if args.mode == "both" else (args.mode,)
    print(f"FRI link, {args.cycle_ms} ms cycle, emulator in real time (own process), loopback")
    for mode in modes:
        r = bench(mode, args.seconds, args.cycle_ms)
        print(
            f"{mode:>9}: {int(r['cycles'])} cycles in {r['wall_s']:.2f} s; driver turnaround "
            f"p50 {r['turn_p50']:.0f} us, p99 {r['turn_p99']:.0f} us, p99.9 "
            f"{r['turn_p999']:.0f} us, max {r['turn_max']:.0f} us; KRC latency p50 "
            f"{r['krc_lat_p50']:.0f} us, p99 {r['krc_lat_p99']:.0f} us; missed "
            f"{int(r['missed'])}, lost {int(r['lost_in'])}, runner late {int(r['deadline'])}"
        )
        print(f"           states {r['states']}, quality {r['qualities']}")
        print(f"           emulator: {r['summary']}")


if __name__ == "__main__":
    main()
