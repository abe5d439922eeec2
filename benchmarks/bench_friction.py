"""Frames per second of ``ffexp friction estimate`` vs bare ``cv2.VideoCapture`` decoding.

Renders a 1280x720, 50 fps FFV1 video of a block sliding the whole time (so
every frame is tracked) in a temporary directory, then alternates, a few
times, a bare decode of the file (``VideoCapture.read`` until the end) and the
full estimate (decode, grey conversion, tracking, fit), and prints the median
frames per second of each and their ratio.

Run: ``python benchmarks/bench_friction.py [--repeats N] [--duration S] [--codec C]``.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from ffexp.friction import Scale, SynthConfig, estimate_video, write_video


def bare_decode(path: Path) -> int:
    """Decode every frame; return the number of frames."""
    cap = cv2.VideoCapture(str(path))
    n = 0
    try:
        while True:
            ok, _ = cap.read()
            if not ok:
                break
            n += 1
    finally:
        cap.release()
    return n


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--duration", type=float, default=4.0, help="video length (s)")
    parser.add_argument("--codec", choices=["ffv1", "png", "mjpg"], default="ffv1")
    args = parser.parse_args()
    cfg = SynthConfig(mu=0.005, v0_mps=0.15, duration_s=args.duration, rest_s=0.5, px_per_m=1130.0)
    with tempfile.TemporaryDirectory() as tmp:
        video = Path(tmp) / "bench.avi"
        t0 = time.perf_counter()
        write_video(cfg, video, np.random.default_rng(1), codec=args.codec)
        print(
            f"video: {cfg.width_px}x{cfg.height_px} @ {cfg.fps:g} fps, {cfg.n_frames} frames, "
            f"{args.codec}, {video.stat().st_size / 1e6:.1f} MB "
            f"(rendered in {time.perf_counter() - t0:.1f} s)"
        )
        bare_fps: list[float] = []
        est_fps: list[float] = []
        ratios: list[float] = []
        result = None
        for i in range(args.repeats):
            # alternate the order so that neither side always runs on a warm cache
            for which in ("bare", "est") if i % 2 == 0 else ("est", "bare"):
                t0 = time.perf_counter()
                if which == "bare":
                    bare = bare_decode(video) / (time.perf_counter() - t0)
                else:
                    result = estimate_video(video, Scale(px_per_m=cfg.px_per_m))
                    est = result.track.frames_read / (time.perf_counter() - t0)
            bare_fps.append(bare)
            est_fps.append(est)
            ratios.append(est / bare)
        assert result is not None
        d = result.to_dict()
        print(f"estimate: mu = {d['mu']:.6f} (true {cfg.mu}), {d['frames_used']} frames fitted")
        print(f"bare decode fps (median of {args.repeats}): {statistics.median(bare_fps):.1f}")
        print(f"estimate fps    (median of {args.repeats}): {statistics.median(est_fps):.1f}")
        print(f"ratio estimate/decode (median of per-run ratios): {statistics.median(ratios):.2f}")
        extra_ms = 1e3 / statistics.median(est_fps) - 1e3 / statistics.median(bare_fps)
        print(f"tracking cost on top of decoding: {extra_ms:.2f} ms/frame")


if __name__ == "__main__":
    main()
