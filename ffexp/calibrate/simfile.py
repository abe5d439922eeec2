"""``ffexp resimulate``: a recording replayed into the simulator, written as a recording.

The simulated measurements go on the recording's own topics and log times
(``/robot/state``, ``/ft/raw``; the commands are the recording's own),
so ``ffexp diff RUN.mcap SIM.mcap`` pairs them cycle by cycle and says where
the simulated rig parts from the real one. The simulated F/T gets the
recording's bias (estimated over its quiet start) and the scene's sensor delay;
it has no noise, so compare with a tolerance of the sensor's noise (``--atol``).
"""

from __future__ import annotations

import json
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ffexp.calibrate.inputs import ReplayInput, read_input, replaying_robot
from ffexp.calibrate.params import FITTABLE
from ffexp.calibrate.residuals import Comparison, compare, ft_on_recorded, outcomes
from ffexp.calibrate.resim import Trace, base_scene, replay_scene_file, rollout
from ffexp.calibrate.scene_out import scene_text
from ffexp.errors import ConfigError, InputError
from ffexp.recording import Recorder, load


@dataclass(frozen=True)
class Resimulated:
    path: Path
    comparison: Comparison
    shift: int
    outcome_recorded: str
    outcome_simulated: str
    failed: str | None


def _write(path: Path, inp: ReplayInput, tr: Trace, shift: int, bias: np.ndarray,
           t0_ns: int, robot_t0_ns: int, source: Path) -> None:
    n = min(inp.cycles, int(np.isfinite(tr.t_s).sum()))
    ft = ft_on_recorded(inp, tr, shift) + bias
    if tr.scene is None:  # (a replay runs in a scene)
        raise TypeError("a replay without its scene")
    joints = tr.scene.arm.description.joints
    with Recorder(path) as rec:
        # not a run's recording (no runner, no phases): its own metadata name, so that a
        # reader does not take the missing run end for a run that ended abnormally
        rec.metadata("resimulation", {"resimulated_from": str(source), "driver": inp.robot,
                                      "scene_json": tr.scene.model_dump_json(),
                                      "ft_delay_samples": str(shift)})
        state = rec.record("/robot/state")
        for k in range(n):
            state["time_ns"] = robot_t0_ns + round(tr.t_s[k] * 1e9)
            state["tcp_pose"] = tr.pose[k].reshape(-1)
            state["joint_pos"] = tr.joints[k]
            state["n_joints"] = joints
            state["commanding"] = int(inp.commanding[k])
            state["healthy"] = 1
            state["cycle"] = k
            state["cycle_s"] = inp.cycle_s
            if tr.twist is not None:
                state["has_twist"] = 1
                state["twist"] = tr.twist[k]
            if tr.ext_wrench is not None:
                state["has_ext_wrench"] = 1
                state["ext_wrench"] = tr.ext_wrench[k]
            rec.write("/robot/state", t0_ns + round(inp.t_s[k] * 1e9))
        ok = np.isfinite(ft).all(axis=1)
        sample = rec.record("/ft/raw")
        for i in np.flatnonzero(ok):
            sample["wrench"] = ft[i]
            sample["seq"] = int(i)
            rec.write("/ft/raw", t0_ns + round(inp.ft_t_s[i] * 1e9))


def resimulate(recording: Path, out: Path, scene_file: Path | None = None,
               overrides: Sequence[str] = ()) -> Resimulated:
    """Replay ``recording`` into the simulator and write what it measured to ``out``.

    The scene: ``scene_file`` (with ``overrides``), else the recording's own (a
    simulator's run), else bad input.
    """
    if out.exists() and out.is_dir():
        raise ConfigError("--out", str(out), "is a directory; give the recording's file name")
    if out.resolve() == recording.resolve():
        raise ConfigError("--out", str(out), "is the recording itself")
    recorded = scene_file is None
    with tempfile.TemporaryDirectory() as tmp:
        if scene_file is None:
            meta = load(recording, ["/robot/state"]).metadata.get("run", {})
            if "scene_json" not in meta:
                raise InputError(f"{recording}: no scene in this recording (not a simulator's "
                                 "run); give --scene")
            scene_file = Path(tmp) / "recorded-scene.toml"
            scene_file.write_text(scene_text(json.loads(meta["scene_json"]), [], {}))
        try:
            scene = base_scene(scene_file, overrides, replaying_robot([recording]))
        except ConfigError as exc:
            if not recorded or exc.source != str(scene_file):
                raise
            # the recording's own scene, written to a temporary file: name the recording
            raise ConfigError(f"{recording} (its recorded scene)", exc.field,
                              exc.message) from None
        inp = read_input(recording, scene, tuple(FITTABLE))
        tr = rollout(inp, replay_scene_file(scene_file, scene, Path(tmp)), overrides)
    shift = 0 if inp.ft_estimate else round(  # the robot's own estimate: no delay
        float(scene["ft_sensor"]["delay_s"]) * float(scene["ft_sensor"]["rate"]))
    comp = compare(inp, tr, shift)
    rec_o, sim_o = outcomes(inp, tr, shift)
    full = load(recording, ["/robot/state"])
    t0 = full.run_start_ns
    robot_t0 = int(full.topic("/robot/state")["time_ns"][0])
    tmp_out = out.with_name(out.name + ".part")
    _write(tmp_out, inp, tr, shift, comp.bias, t0, robot_t0, recording)
    tmp_out.replace(out)
    return Resimulated(out, comp, shift, rec_o.text(), sim_o.text(), tr.failed)
