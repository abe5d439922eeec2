"""Replay a recording's applied commands, open loop, into the simulated rig: :func:`rollout`.

The simulator is reached through the neutral seams only: a rig of the simulated
robot that replays the recording (:attr:`ReplayInput.robot`, its table from its
:class:`~drivers.base.backend.Replay`) opened by
:func:`drivers.factory.open_devices` with the base scene and overrides (the
recording's start, the candidate parameters, a noise-free sensor), then
``robot.send()`` of the recorded command of every cycle (``None`` while the
recorded robot did not command, the KRC mirroring, or held on its own), collecting each
:class:`~drivers.base.types.RobotState` and the F/T samples.

The simulated F/T sensor runs without noise, bias, drift or delay: the
recording's bias is estimated per recording and its delay is a shift of the
simulated series (:mod:`ffexp.calibrate.residuals`), so neither needs a
rollout of its own.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from drivers import registry
from drivers.base.backend import OpenContext, RobotBackend
from drivers.base.types import CartesianCommand
from drivers.description import load_scene
from drivers.description.scene import Scene
from drivers.factory import open_devices
from drivers.rig import validate_rig
from ffexp import compiled
from ffexp.calibrate.inputs import ReplayInput, default_robot
from ffexp.calibrate.scene_out import scene_text
from ffexp.errors import FfexpError, SimulationError
from ffexp.recording.topics import STATE_JOINTS
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
    """(n, STATE_JOINTS) [rad] (NaN past the arm's joints)"""
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
    scene: Scene | None = None
    """The scene the replay ran in."""

    @property
    def tcp(self) -> np.ndarray:
        """(n, 3) TCP positions [m]."""
        return self.pose[:, :3, 3]


def _rig(inp: ReplayInput) -> Any:
    replay = registry.robot_backend(inp.robot).replay
    assert replay is not None  # (read_input chose a robot that replays)
    return validate_rig({"robot": {**replay.table(inp.start_cycles, inp.wire_precision),
                                   **inp.robot_settings},
                         "ft": {"type": inp.ft_type, **inp.ft_settings}}, _SOURCE)


def base_scene(scene_file: Path, overrides: Sequence[str] = (),
               robot: RobotBackend[Any] | None = None) -> dict[str, Any]:
    """The scene the simulated ``robot`` (default: the default rig's) runs in from
    ``scene_file`` and ``overrides``, as JSON data; read, no world built. A robot that
    puts its arm in the place of another (a UR5e, an FR3) does so here as in a run.

    Raises :class:`~ffexp.errors.ConfigError` naming the file and key of a bad value.
    """
    if robot is None:
        robot = default_robot()
    if robot.scene is None or robot.replay is None:  # (a replaying robot is simulated)
        raise TypeError(f"robot {robot.rig_type!r} states no scene")
    cfg = validate_rig({"robot": robot.replay.table(0, False),
                        "ft": {"type": robot.default_ft}}, _SOURCE).robot
    scene = robot.scene(cfg, OpenContext(_SOURCE, scene_file, tuple(overrides)))
    data: dict[str, Any] = scene.model_dump(mode="json")
    return data


def replay_scene_file(scene_file: Path, base: dict[str, Any], tmp: Path) -> Path:
    """The scene file a replay starts from: ``scene_file`` itself, or, when the replaying
    robot put its arm in the place of the file's (a UR5e or an FR3 in the paper's scene),
    ``base`` (that scene, :func:`base_scene`) written to ``tmp``: the recordings' start
    overrides are that arm's (its joints), which the file's own arm would refuse."""
    if load_scene(scene_file).arm.model == base["arm"]["model"]:
        return scene_file
    path = tmp / f"{scene_file.stem}-{base['arm']['model']}.toml"
    path.write_text(scene_text(base, [f"{scene_file} with the {base['arm']['model']} arm "
                                      "in its place (calibration replay)"], {}),
                    encoding="utf-8")
    return path


def rollout(inp: ReplayInput, scene_file: Path, overrides: Sequence[str] = ()) -> Trace:
    """Replay ``inp``'s commands in the scene ``scene_file`` + ``overrides``."""
    n = inp.cycles
    devices = open_devices(_rig(inp), source=_SOURCE, scene_file=scene_file,
                           scene_overrides=[*inp.start_overrides, *QUIET, *overrides],
                           seed=inp.seed)
    robot, sensor = devices.robot, devices.sensor
    pose = np.full((n, 4, 4), np.nan)
    joints = np.full((n, STATE_JOINTS), np.nan)
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
    compiled.load_kernels()  # every kernel compiled or loaded now: none in the loop
    try:
        robot.connect()
        sensor.start()
        for k, state in enumerate(robot.measurements()):
            if t0 is None:
                t0 = state.time_ns
            t_s[k] = (state.time_ns - t0) / 1e9
            pose[k] = state.tcp_pose_m
            q = state.joint_pos_rad[:STATE_JOINTS]
            joints[k, :q.shape[0]] = q
            if state.tcp_twist_mps_radps is not None:
                twist[k] = state.tcp_twist_mps_radps
            if state.ext_wrench_n_nm is not None:
                ext[k] = state.ext_wrench_n_nm
            truth = state.truth
            if truth is not None:
                body = truth.body("target")
                if body is not None:  # in the arm's base frame, as a tracker sees it
                    p = body.pose if truth.base_pose is None else \
                        np.linalg.inv(truth.base_pose) @ body.pose
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
            if inp.commanding[k] and not inp.held[k]:
                cmd.pose_m[...] = inp.pose[k]
                cmd.stiffness_npm_nmprad[...] = inp.stiffness[k]
                cmd.damping_ratio[...] = inp.damping[k]
                cmd.wrench_n_nm[...] = inp.wrench[k]
                robot.send(cmd)
            else:
                robot.send(None)
    except SimulationError as exc:
        failed = f"simulation diverged at cycle {k}: {exc}"
    except FfexpError as exc:  # the robot stopped the arm (a limit, a reflex), a bad command
        failed = f"replay stopped at cycle {k}: {exc}"
    finally:
        devices.close()
    scene = devices.scene
    if scene is None:  # (a replaying robot is a simulated one)
        raise TypeError(f"robot {inp.robot!r} replays without a scene")
    return Trace(t_s=t_s, pose=pose, joints=joints,
                 ft_t_s=np.concatenate(ft_t) if ft_t else np.zeros(0),
                 ft=np.concatenate(ft_w) if ft_w else np.zeros((0, 6)),
                 target=target, seated=seated, in_contact=contact, failed=failed,
                 twist=twist if np.isfinite(twist[0]).all() else None,
                 ext_wrench=ext if np.isfinite(ext[0]).all() else None,
                 scene=scene)
