"""Recorder throughput and ``load`` speed against the bare mcap library, same run.

    python benchmarks/bench_recording.py [--seconds S] [--repeats R]

Writes the message mix of a paper run (per 5 ms cycle: measurement, link,
command, estimator, control terms, sim truth, five F/T samples; a /tf
transform pair every 20 ms) for ``S`` seconds of run time:

- recorder: ``Recorder.write`` of filled records (encoding = ``tobytes``);
- bare: ``mcap.writer.Writer.add_message`` of the very same bytes, prepared
  beforehand, with the same chunk size and compression;
- load: ``ffexp.recording.load`` of the file into numpy arrays, against bare
  ``iter_messages`` over the same file (which decodes nothing).

Prints medians over the repeats and the ratios.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from ffexp.recording import Recorder, load
from ffexp.recording.recorder import CHUNK_SIZE_BYTES
from ffexp.recording.topics import CDR_TOPICS

CYCLE_NS = 5_000_000
T0 = 1_750_000_000 * 10**9
PER_CYCLE = ("/robot/measurement", "/robot/link", "/robot/command", "/estimator/state",
             "/control/terms", "/sim/truth")


VARIANTS = 64


def make_records(rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Per topic, VARIANTS different records of noisy numbers (compress like real data)."""
    out = {}
    for topic, t in CDR_TOPICS.items():
        recs = np.repeat(t.spec.new_record(), VARIANTS)
        for name in recs.dtype.names or ():
            if name != "_cdr_header" and recs[name].dtype.kind == "f":
                recs[name] = rng.normal(size=recs[name].shape)
        out[topic] = recs
    return out


def write_recorder(path: Path, cycles: int, records: dict[str, np.ndarray]) -> float:
    pose = np.eye(4)
    ft = records["/ft/raw"]
    t0 = time.perf_counter()
    with Recorder(path) as rec:
        slots = {topic: rec.record(topic) for topic in PER_CYCLE}
        for k in range(cycles):
            t = T0 + k * CYCLE_NS
            v = k % VARIANTS
            for topic in PER_CYCLE:
                slots[topic][0] = records[topic][v]  # what the runner's filling leaves
                rec.write(topic, t)
            j = (5 * k) % (VARIANTS - 5)
            rec.write_records(
                "/ft/raw", t - CYCLE_NS + np.arange(1, 6) * 1_000_000, ft[j : j + 5]
            )
            if k % 4 == 0:
                rec.transform(t, "base", "tool", pose)
                rec.transform(t, "base", "target", pose)
    return time.perf_counter() - t0


def write_bare(path: Path, cycles: int, records: dict[str, np.ndarray]) -> float:
    import json

    payload = {t: [r.tobytes() for r in recs] for t, recs in records.items()}
    tf = json.dumps({"timestamp": {"sec": 0, "nsec": 0}, "parent_frame_id": "base",
                     "child_frame_id": "tool", "translation": {"x": 0, "y": 0, "z": 0},
                     "rotation": {"x": 0, "y": 0, "z": 0, "w": 1}}).encode()
    t0 = time.perf_counter()
    with path.open("wb") as fh:
        w = Writer(fh, chunk_size=CHUNK_SIZE_BYTES, compression=CompressionType.ZSTD)
        w.start()
        ids = {}
        for topic in CDR_TOPICS:
            sid = w.register_schema(topic, "ros2msg", b"")
            ids[topic] = w.register_channel(topic, "cdr", sid)
        sid = w.register_schema("foxglove.FrameTransform", "jsonschema", b"{}")
        ids["/tf"] = w.register_channel("/tf", "json", sid)
        for k in range(cycles):
            t = T0 + k * CYCLE_NS
            v = k % VARIANTS
            for topic in PER_CYCLE:
                w.add_message(ids[topic], t, payload[topic][v], t)
            j = (5 * k) % (VARIANTS - 5)
            for i in range(5):
                ts = t - CYCLE_NS + (i + 1) * 1_000_000
                w.add_message(ids["/ft/raw"], ts, payload["/ft/raw"][j + i], ts)
            if k % 4 == 0:
                w.add_message(ids["/tf"], t, tf, t)
                w.add_message(ids["/tf"], t, tf, t)
        w.finish()
    return time.perf_counter() - t0


def read_ours(path: Path) -> float:
    t0 = time.perf_counter()
    load(path)
    return time.perf_counter() - t0


def read_bare(path: Path) -> float:
    t0 = time.perf_counter()
    with path.open("rb") as fh:
        for _ in make_reader(fh).iter_messages(log_time_order=False):
            pass
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0, help="run time written per repeat")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    cycles = round(args.seconds / 0.005)
    records = make_records(np.random.default_rng(0))
    msgs = cycles * (len(PER_CYCLE) + 5) + 2 * ((cycles + 3) // 4)
    ours_w, bare_w, ours_r, bare_r = [], [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        a, b = Path(tmp) / "ours.mcap", Path(tmp) / "bare.mcap"
        for _ in range(args.repeats):
            ours_w.append(write_recorder(a, cycles, records))
            bare_w.append(write_bare(b, cycles, records))
            ours_r.append(read_ours(a))
            bare_r.append(read_bare(a))
        size_mb = a.stat().st_size / 1e6
    ow, bw = statistics.median(ours_w), statistics.median(bare_w)
    orr, br = statistics.median(ours_r), statistics.median(bare_r)
    print(f"{args.seconds:g} s of a paper run: {cycles} cycles, {msgs} messages, {size_mb:.1f} MB")
    print(f"write  recorder: {msgs / ow:9.0f} msg/s  ({args.seconds / ow:6.1f}x real time)")
    print(f"write  bare mcap: {msgs / bw:8.0f} msg/s  (same bytes, prepared)")
    print(f"write  ratio recorder/bare: {bw / ow:.2f}")
    print(f"load   ffexp.recording.load: {msgs / orr:8.0f} msg/s (numpy arrays per topic)")
    print(f"load   bare iter_messages:   {msgs / br:8.0f} msg/s (no decoding)")
    print(f"load   ratio load/bare: {br / orr:.2f}")


if __name__ == "__main__":
    main()
