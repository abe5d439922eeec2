"""The control loop's cycle time with and without ``--live``, in the same run.

    python benchmarks/bench_live.py [--protocol P] [--seconds S] [--repeats R]

Runs the protocol (default Method I case I) for ``S`` seconds of simulated time
through ``ffexp.experiment.run_file`` on the built-in sim rig (lockstep, as
fast as physics allows), in four ways per repeat, interleaved:

* bare: the recording only (the 3-D scene included: it is part of every run);
* live: the same with the live server (``LiveOptions(port=0)``), no viewer;
* bare again: as bare (the spread of the two is the noise of the machine);
* live + viewer: the same with one WebSocket client (``websockets``, Foxglove's
  protocol) subscribed to every topic and reading everything it is sent.

A cycle's wall time is the time between two calls of the loop's
``stop_requested`` callback (once per cycle). Prints the median cycle time of
each (over every cycle of every repeat) and the ratios to bare; the goal is
within 10 % (issue 15).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import re
import statistics
import tempfile
import threading
import time
from itertools import pairwise
from pathlib import Path

import websockets

from ffexp.experiment import run_file
from ffexp.live import LiveOptions

ROOT = Path(__file__).resolve().parent.parent
#: Foxglove's WebSocket subprotocols (foxglove-sdk 0.30 answers with the second).
SUBPROTOCOLS = ["foxglove.websocket.v1", "foxglove.sdk.v1"]


class Viewer:
    """A client in its own thread: subscribes to every advertised channel, reads until closed."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.messages = 0
        self.stop = threading.Event()
        self.thread = threading.Thread(target=lambda: asyncio.run(self._main()), daemon=True)
        self.thread.start()

    async def _main(self) -> None:
        async with websockets.connect(self.url, subprotocols=SUBPROTOCOLS,
                                      close_timeout=0.5, max_size=None) as ws:
            sub = 0
            while not self.stop.is_set():
                try:
                    frame = await asyncio.wait_for(ws.recv(), 0.5)
                except TimeoutError:
                    continue
                except websockets.ConnectionClosed:
                    return
                if isinstance(frame, str):
                    msg = json.loads(frame)
                    if msg.get("op") == "advertise":
                        subs = []
                        for ch in msg["channels"]:
                            sub += 1
                            subs.append({"id": sub, "channelId": ch["id"]})
                        await ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
                else:
                    self.messages += 1


def one_run(ppath: Path, seconds: float, out: Path, mode: str) -> tuple[list[float], int]:
    stamps: list[float] = []
    clock = time.perf_counter
    viewers: list[Viewer] = []

    def tick() -> bool:
        stamps.append(clock())
        return False

    def notice(line: str) -> None:
        m = re.search(r"ws://\S+", line)
        if m and mode == "live + viewer":
            viewers.append(Viewer(m.group(0)))

    run_file(ppath, [f"run.timeout_s={seconds}", "run.stop_hold_s=0"], out_dir=out,
             stop_requested=tick, notice=notice,
             live=None if mode.startswith("bare") else LiveOptions(port=0))
    received = 0
    for v in viewers:
        v.stop.set()
        v.thread.join(5.0)
        received += v.messages
    return [b - a for a, b in pairwise(stamps)], received


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--protocol", type=Path, default=ROOT / "protocols/method1_case1.toml")
    ap.add_argument("--seconds", type=float, default=4.0)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    modes = ("bare", "live", "bare again", "live + viewer")
    cycles: dict[str, list[float]] = {m: [] for m in modes}
    received = 0
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(args.repeats):
            for mode in modes:
                dts, got = one_run(args.protocol, args.seconds, Path(tmp), mode)
                cycles[mode].extend(dts)
                received += got
    base = statistics.median(cycles["bare"])
    print(f"{args.protocol.name}, {args.seconds:g} s simulated, {args.repeats} repeats, "
          f"cycles per mode: {len(cycles['bare'])}")
    for mode in modes:
        med = statistics.median(cycles[mode])
        print(f"  {mode:14s} median cycle {med * 1e6:8.1f} us   ratio to bare {med / base:.3f}")
    print(f"  the viewer received {received} messages in all")


if __name__ == "__main__":
    main()
