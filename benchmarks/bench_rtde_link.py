"""The RTDE link in real time: our RTDE server at 500 Hz over loopback, ffexp's client or ur_rtde.

Run (60 s per client, as the acceptance of the UR back-end asks)::

    python benchmarks/bench_rtde_link.py --seconds 60 --rt on --pin

Options: ``--client ffexp|ur_rtde|both``; ``--rt off|on`` (SCHED_FIFO where the OS
allows it, the collector frozen, for both processes; ``ffexp.rt.realtime``);
``--pin`` (with ``--rt``: the server on CPU 0, the client on CPU 1).

The server (:class:`drivers.ur.emulate.rtde_server.RtdeServer`, real-time pacing
at 500 Hz) runs as its own process, as a controller is its own machine. Its
data source stamps each step (``time.perf_counter_ns``, just before the
step's package is packed and sent) and writes the step number into
``output_int_register_0``; its input sink stamps each answer.

- ``ffexp`` client (:class:`drivers.ur.rtde.client.RtdeClient`): answers every
  package at once with the step number in ``input_int_register_0``.
  Turnaround = answer received - step stamped (p50, p99, p99.9, max); a
  missed cycle is a step whose answer had not come when the next step
  began, or never came. Every package's ``timestamp``, ``actual_q``,
  ``actual_TCP_pose`` and ``actual_TCP_force`` are compared with what the
  source produced for that step.
- ``ur_rtde`` client (``RTDEReceiveInterface`` on the server's own
  127.0.0.x:30004; it sends nothing back): every value read compared with
  the source's, and how many distinct packages the poll read (ur_rtde keeps
  only the newest package, so this counts the poll, not the link).

Also printed: the server's own late steps (a cycle it began more than a
period late and skipped). Nothing here is asserted: these are measurements of
this machine, as it is loaded.
"""

from __future__ import annotations

import argparse
import json
import os
import select
import socket
import subprocess
import sys
import time
from contextlib import nullcontext
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
VARIABLES = ("timestamp", "actual_q", "actual_TCP_pose", "actual_TCP_force")
BASE_HZ = 500.0


def produced(k: int) -> dict[str, Any]:
    """The source's values at step k (each vector tells its step)."""
    return {"timestamp": k / BASE_HZ, "actual_q": k * 1e-3 + np.arange(6) / 8,
            "actual_TCP_pose": np.array([0.4, 0.1, 0.3, 0.0, 3.1, 0.0]) + k * 1e-5,
            "actual_TCP_force": -np.arange(6) - k * 0.5, "output_int_register_0": k}


# ----------------------------------------------------------------------------- the server


def serve(host: str, port: int, rt: bool, pin: bool) -> None:
    """The child: serve until stdin closes, then print the link's figures as one JSON line."""
    from drivers.ur.emulate.rtde_server import RtdeServer
    from ffexp.rt import realtime

    step_ns: list[int] = []
    answer_ns: dict[int, int] = {}

    def source() -> dict[str, Any]:
        k = len(step_ns)
        step_ns.append(time.perf_counter_ns())
        return produced(k)

    def sink(values: Any) -> None:
        answer_ns.setdefault(int(values["input_int_register_0"]), time.perf_counter_ns())

    with realtime((0,) if pin else ()) if rt else nullcontext() as report:
        srv = RtdeServer(source, sink, host=host, port=port, pacing="realtime",
                         base_hz=BASE_HZ, outputs=(*VARIABLES, "output_int_register_0"),
                         lockstep_wait_inputs=False)
        with srv:
            print(json.dumps({"port": srv.port, "rt": str(report or "off")}), flush=True)
            sys.stdin.read()
            counters = dict(srv.counters)
    steps = np.array(step_ns, dtype=np.int64)
    answered = np.array(sorted(answer_ns), dtype=np.int64)
    answered = answered[(answered >= 0) & (answered < len(steps))]
    turn_ms = (np.array([answer_ns[int(k)] for k in answered]) - steps[answered]) / 1e6
    in_time = np.array([k + 1 >= len(steps) or answer_ns[int(k)] < steps[k + 1]
                        for k in answered], dtype=bool)
    print(json.dumps({"steps": len(steps), "answered": len(answered),
                      "answered_in_time": int(in_time.sum()),
                      "turnaround_ms": turn_ms.tolist(), "counters": counters}), flush=True)


# ----------------------------------------------------------------------------- the clients


def start_server(host: str, port: int, rt: bool, pin: bool) -> tuple[subprocess.Popen[str], dict]:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get(
        "PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, __file__, "serve", host, str(port),
                             "rt" if rt else "-", "pin" if pin else "-"],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)
    assert proc.stdout is not None
    ready, _, _ = select.select([proc.stdout], [], [], 60.0)
    if not ready:
        proc.kill()
        raise SystemExit("the RTDE server did not start within 60 s")
    return proc, json.loads(proc.stdout.readline())


def stop_server(proc: subprocess.Popen[str]) -> dict[str, Any]:
    assert proc.stdin is not None and proc.stdout is not None
    proc.stdin.close()
    line = proc.stdout.readline()
    proc.wait(30.0)
    return dict(json.loads(line))


def check(k: int, values: dict[str, Any]) -> bool:
    want = produced(k)
    return all(np.array_equal(np.asarray(values[n]), np.asarray(want[n])) for n in VARIABLES)


def run_ffexp(seconds: float, rt: bool, pin: bool) -> dict[str, Any]:
    from drivers.ur.rtde.client import RtdeClient
    from ffexp.rt import realtime

    proc, hello = start_server("127.0.0.1", 0, rt, pin)
    mismatches = 0
    with realtime((1,) if pin else ()) if rt else nullcontext():
        client = RtdeClient("127.0.0.1", hello["port"], timeout_s=5.0)
        client.connect()
        client.setup_outputs([*VARIABLES, "output_int_register_0"], BASE_HZ)
        inputs = client.setup_inputs(["input_int_register_0"])
        client.start()
        answer = inputs.empty()
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            rec = client.receive().record
            k = int(rec["output_int_register_0"])
            answer["input_int_register_0"] = k
            client.send(inputs, answer)
            mismatches += not check(k, {n: rec[n] for n in VARIABLES})
        client.close()
    result = stop_server(proc)
    result.update(client="ffexp", rt=hello["rt"], mismatches=mismatches)
    return result


def free_loopback_host() -> str:
    for i in range(200):
        host = f"127.0.0.{20 + (os.getpid() + i) % 200}"
        with socket.socket() as s:
            try:
                s.bind((host, 30004))
            except OSError:
                continue
        return host
    raise SystemExit("no loopback address with a free port 30004")


def run_ur_rtde(seconds: float, rt: bool, pin: bool) -> dict[str, Any]:
    import rtde_receive  # the test extra

    host = free_loopback_host()
    proc, hello = start_server(host, 30004, rt, pin)
    seen: set[int] = set()
    mismatches = 0
    receiver = rtde_receive.RTDEReceiveInterface(host, BASE_HZ, list(VARIABLES))
    end = time.monotonic() + seconds
    stamp = -1.0
    while time.monotonic() < end:
        if receiver.getTimestamp() == stamp:
            os.sched_yield()
            continue
        values = {"timestamp": receiver.getTimestamp(), "actual_q": receiver.getActualQ(),
                  "actual_TCP_pose": receiver.getActualTCPPose(),
                  "actual_TCP_force": receiver.getActualTCPForce()}
        stamp = values["timestamp"]
        k = round(stamp * BASE_HZ)
        seen.add(k)
        # the four getters may straddle a new package: judge the vectors by their own step
        q_step = round((values["actual_q"][0]) * 1e3)
        mismatches += not (np.array_equal(values["timestamp"], produced(k)["timestamp"])
                           and np.array_equal(values["actual_q"], produced(q_step)["actual_q"]))
    receiver.disconnect()
    result = stop_server(proc)
    result.update(client="ur_rtde", rt=hello["rt"], packages_seen=len(seen),
                  mismatches=mismatches)
    return result


def report(r: dict[str, Any]) -> None:
    c = r["counters"]
    head = (f"{r['client']:7s} --rt {r['rt']}: {r['steps']} steps, {c.get('sent', 0)} sent, "
            f"server late steps {c.get('late_steps', 0)}, value mismatches {r['mismatches']}")
    if r["client"] == "ur_rtde":
        print(f"{head}; distinct packages read {r['packages_seen']} (ur_rtde keeps only the "
              "newest: a Python poll does not see them all)")
        return
    turn = np.array(r["turnaround_ms"])
    missed = r["steps"] - r["answered_in_time"]
    q = np.percentile(turn, [50, 99, 99.9]) if turn.size else [np.nan] * 3
    print(f"{head}; turnaround p50 {q[0]:.3f} ms, p99 {q[1]:.3f} ms, p99.9 {q[2]:.3f} ms, "
          f"max {turn.max() if turn.size else np.nan:.3f} ms; missed cycles {missed} "
          f"({100 * missed / max(1, r['steps']):.3f} %)")


def main() -> None:
    if sys.argv[1:2] == ["serve"]:
        serve(sys.argv[2], int(sys.argv[3]), sys.argv[4] == "rt", sys.argv[5] == "pin")
        return
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--client", choices=("ffexp", "ur_rtde", "both"), default="both")
    ap.add_argument("--rt", choices=("off", "on"), default="off")
    ap.add_argument("--pin", action="store_true")
    args = ap.parse_args()
    rt = args.rt == "on"
    if args.client in ("ffexp", "both"):
        report(run_ffexp(args.seconds, rt, args.pin))
    if args.client in ("ur_rtde", "both"):
        report(run_ur_rtde(args.seconds, rt, args.pin))


if __name__ == "__main__":
    main()
