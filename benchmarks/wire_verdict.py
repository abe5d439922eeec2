"""The verdict over the wire against the truth: each protocol over FRI against ``ffexp emulate``
with the camera tracker reading the emulator's stream, beside the same protocol in-process
judged by the simulator's truth (same seed, same scene overrides).

    python benchmarks/wire_verdict.py [--out DIR] [--scenes K] [--seed S] [--port-base P]

With ``--scenes 0`` (default) only the paper's four protocols in the paper's
scene; with ``K > 0`` also ``K`` perturbed scenes (target lateral offset and
yaw drawn around the paper's, seeded). The emulator runs in lockstep (the
camera renders at wall-clock 50 fps whatever the simulation's speed). Prints
one line per run (wire verdict, truth verdict, agree) and the agreement rate.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PY = sys.executable
PAPER = ["method1_case1.toml", "method1_case2.toml", "method2.toml", "method3_impedance.toml"]


def final_verdict(path: Path) -> dict[str, str]:
    """The recording's final ``/alignment/verdict`` ({} when there is none)."""
    from ffexp.analysis import final_verdict as final_of
    from ffexp.recording import load

    return {k: v for k, v in final_of(load(path)).items() if isinstance(v, str)}


def wire(protocol: str, seed: int, scene_set: list[str], out: Path, port: int) -> dict[str, str]:
    cal = out / f"calibration-{port}.toml"
    emu_cmd = [PY, "-m", "ffexp", "emulate", "--remote", f"127.0.0.1:{port}", "--pacing",
               "lockstep", "--seed", str(seed), "--netft-port", str(port + 1), "--camera-port",
               str(port + 2), "--camera-calibration", str(cal)]
    for s in scene_set:
        emu_cmd += ["--set", s]
    emu = subprocess.Popen(emu_cmd, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        assert emu.stderr is not None
        line = emu.stderr.readline()  # the ready line
        if "ffexp emulate:" not in line:
            raise RuntimeError(line)
        cmd = [PY, "-m", "ffexp", "run", str(ROOT / "protocols" / protocol), "--rig",
               str(ROOT / "rigs" / "emulator.toml"), "--fri-port", str(port), "--netft",
               f"127.0.0.1:{port + 1}", "--camera", f"http://127.0.0.1:{port + 2}/stream.mjpg",
               "--rig-set", f"tracker.calibration='{cal}'", "--out", str(out / "wire")]
        if scene_set:
            cmd += ["--set", f"scene.set={json.dumps(scene_set)}"]
        run = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, timeout=900)
    finally:
        emu.terminate()
        try:
            emu.wait(10)
        except subprocess.TimeoutExpired:
            emu.kill()
    m = re.search(r"recording: (\S+)", run.stdout)
    if m is None:
        return {"label": "error", "source": run.stderr.strip()[-200:]}
    return final_verdict(Path(m.group(1)))


def local(protocol: str, scene_set: list[str], out: Path) -> dict[str, str]:
    from ffexp.experiment import run_file

    overrides = [f"scene.set={json.dumps(scene_set)}"] if scene_set else []
    res = run_file(ROOT / "protocols" / protocol, overrides, out_dir=out / "local")
    return final_verdict(res.path)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("runs/wire-verdict"))
    ap.add_argument("--scenes", type=int, default=0)
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--port-base", type=int, default=47100)
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(args.seed)
    cases: list[tuple[str, list[str]]] = [(p, []) for p in PAPER]
    for _ in range(args.scenes):
        sc = [f"target.lateral={rng.uniform(0.006, 0.018):.4f}",
              f"target.yaw_deg={rng.uniform(4.0, 11.0):.2f}"]
        cases += [(p, sc) for p in PAPER]
    agree = 0
    for k, (protocol, sc) in enumerate(cases):
        from ffexp.protocol import load_run_protocol

        seed = load_run_protocol(ROOT / "protocols" / protocol).seed
        t0 = time.monotonic()
        w = wire(protocol, seed, sc, args.out, args.port_base + 3 * (k % 10))
        t = local(protocol, sc, args.out)
        ok = w.get("label") == t.get("label")
        agree += ok
        print(f"{protocol:24s} {' '.join(sc):40s} wire {w.get('label')!s:12s} "
              f"({w.get('source')}) truth {t.get('label')!s:12s} {'agree' if ok else 'DIFFER'}"
              f"  {time.monotonic() - t0:.0f} s", flush=True)
    print(f"agreement: {agree}/{len(cases)}")
    return 0 if agree == len(cases) else 1


if __name__ == "__main__":
    sys.exit(main())
