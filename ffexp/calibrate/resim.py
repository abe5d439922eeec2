"""Replay a recording's applied commands, open loop, into the simulated rig: :func:`rollout`.

The simulator is reached through the neutral seams only: a sim rig
(:mod:`drivers.rig`) opened by :func:`drivers.factory.open_devices` with the
base scene and overrides (the recording's start, the candidate parameters,
a noise-free sensor), then ``robot.send()`` of the recorded command of every
cycle (``None`` while the recorded robot did not command: the KRC mirrors),
collecting each :class:`~drivers.base.types.RobotState` and the F/T samples.

The simulated F/T sensor runs without noise, bias, drift or delay: the
recording's bias is estimated per recording and its delay is a shift of the
simulated series (:mod:`ffexp.calibrate.residuals`), so neither needs a
rollout of its own.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from drivers.base.types import CartesianCommand
from drivers.factory import open_devices
from drivers.rig import validate_rig
from ffexp.calibrate.inputs import ReplayInput
from ffexp.errors import FfexpError, SimulationError
from ffexp.scenarios.funnel import Alignment, truth_placement

#: Overrides that make the simulated sensor an ideal one (no noise, bias, drift, delay).
QUIET = ("ft_sensor.noise_std=[0.0, 0.0]", "ft_sensor.bias_std=[0.0, 0.0]",
         "ft_sensor.drift_density=[0.0, 0.0]", "ft_sensor.delay_s=0.0")
_SOURCE = "<calibration replay>"
#: "Seated" in a replay: the funnel alignment's default tolerances, by the truth.
_ALIGNED = Alignment()


@dataclass(frozen=True)
class Trace:
    """What the simulated rig measured, replaying one recording."""

    t_s: np.ndarray
    pose: np.ndarray
    """(n, 4, 4) TCP poses in the base frame [m]"""
    joints: np.ndarray
    """(n, 7) [rad]"""
    ft_t_s: np.ndarray
    ft: np.ndarray
    """(m, 6) ideal sensor readings [N, N m]"""
    target: np.ndarray
    """(n, 3) the simulated target ``[x, y, yaw]`` in the base frame [m, m, rad]."""
    seated: np.ndarray
    in_contact: np.ndarray
    failed: str | None = None
    """Why the simulation stopped early (diverged), else ``None``."""
    twist: np.ndarray | None = None
    """(n, 6) the robot's reported TCP twist (``None``: it reports none)."""
    ext_wrench: np.ndarray | None = None
    """(n, 6) the robot's external wrench estimate (``None``: it reports none)."""
    scene_json: str = ""
    """The scene the replay ran in."""

    @property
    def tcp(self) -> np.ndarray:
        """(n, 3) TCP positions [m]."""
        return self.pose[:, :3, 3]


def _rig(inp: ReplayInput) -> Any:
    return validate_rig({"robot": {"type": "sim", "start_cycles": inp.start_cycles,
                                   "wire_precision": inp.wire_precision},
                         "ft": {"type": inp.ft_type}}, _SOURCE)


def base_scene(scene_file: Path, overrides: Sequence[str] = ()) -> dict[str, Any]:
    """The scene the simulator builds from ``scene_file`` and ``overrides``, as JSON data.

    Raises :class:`~ffexp.errors.ConfigError` naming the file and key of a bad value.
    """
    devices = open_devices(validate_rig({}, _SOURCE), source=_SOURCE, scene_file=scene_file,
                           scene_overrides=overrides)
    try:
        data: dict[str, Any] = json.loads(devices.metadata["scene_json"])
    finally:
        devices.close()
    return data


def rollout(inp: ReplayInput, scene_file: Path, overrides: Sequence[str] = ()) -> Trace:
    """Replay ``inp``'s commands in the scene ``scene_file`` + ``overrides``."""
    n = inp.cycles
    devices = open_devices(_rig(inp), source=_SOURCE, scene_file=scene_file,
                           scene_overrides=[*inp.start_overrides, *QUIET, *overrides],
                           seed=inp.seed)
    robot, sensor = devices.robot, devices.sensor
    pose = np.full((n, 4, 4), np.nan)
    joints = np.full((n, 7), np.nan)
    target = np.full((n, 3), np.nan)
    seated = np.zeros(n, dtype=bool)
    contact = np.zeros(n, dtype=bool)
    t_s = np.full(n, np.nan)
    twist = np.full((n, 6), np.nan)
    ext = np.full((n, 6), np.nan)
    ft_t: list[np.ndarray] = []
    ft_w: list[np.ndarray] = []
    cmd = CartesianCommand()
    failed: str | None = None
    t0: int | None = None
    k = 0
    try:
        robot.connect()
        sensor.start()
        for k, state in enumerate(robot.measurements()):
            if t0 is None:
                t0 = state.time_ns
            t_s[k] = (state.time_ns - t0) / 1e9
            pose[k] = state.tcp_pose_m
            joints[k] = state.joint_pos_rad[:7]
            if state.tcp_twist_mps_radps is not None:
                twist[k] = state.tcp_twist_mps_radps
            if state.ext_wrench_n_nm is not None:
                ext[k] = state.ext_wrench_n_nm
            truth = state.truth
            if truth is not None:
                body = truth.body("target")
                if body is not None:
                    p = body.pose
                    target[k] = (p[0, 3], p[1, 3], np.arctan2(p[1, 0], p[0, 0]))
                placed = truth_placement(truth, state.tcp_pose_m)
                seated[k] = placed is not None and _ALIGNED.within(placed)
                contact[k] = truth.in_contact
            samples = sensor.samples()
            if len(samples):
                ft_t.append((samples.time_ns - t0) / 1e9)
                ft_w.append(samples.wrench.copy())
            if k == n - 1:
                break
            if inp.commanding[k]:
                cmd.pose_m[...] = inp.pose[k]
                cmd.stiffness_npm_nmprad[...] = inp.stiffness[k]
                cmd.damping_ratio[...] = inp.damping[k]
                cmd.wrench_n_nm[...] = inp.wrench[k]
                robot.send(cmd)
            else:
                robot.send(None)
    except SimulationError as exc:
        failed = f"simulation diverged at cycle {k}: {exc}"
    except FfexpError as exc:  # the KRC stopped the arm (a limit switch), a bad command
        failed = f"replay stopped at cycle {k}: {exc}"
    finally:
        devices.close()
    scene_json = devices.metadata["scene_json"]
    base = np.asarray(json.loads(scene_json)["arm"]["base_pos"])
    target[:, :2] -= base[:2]
    return Trace(t_s=t_s, pose=pose, joints=joints,
                 ft_t_s=np.concatenate(ft_t) if ft_t else np.zeros(0),
                 ft=np.concatenate(ft_w) if ft_w else np.zeros((0, 6)),
                 target=target, seated=seated, in_contact=contact, failed=failed,
                 twist=twist if np.isfinite(twist[0]).all() else None,
                 ext_wrench=ext if np.isfinite(ext[0]).all() else None, scene_json=scene_json)
