"""What a calibration needs of a recording, read once and checked: :class:`ReplayInput`.

A recording can be replayed into the simulator when a simulated robot replays
its robot's recordings (:class:`drivers.base.backend.Replay`: the simulated
LWR4+ those of an LWR4+ behind a KRC, the simulated UR5e a UR's, the simulated
FR3 a Franka's; :func:`replaying_robot`) and it holds the commands as the robot
applied them (set-point, stiffness, damping and superposed wrench of every
cycle, and the cycles it held on its own, on the topic and fields that robot's
back-end states), the states it measured (``/robot/state``) and the F/T samples
(``/ft/raw``). The base scene is the replaying robot's (:func:`ffexp.calibrate.resim.base_scene`:
a UR5e or an FR3 put in the place of a scene's other arm). The tracked
target (``/target/pose``) is used where the rig had a tracker. The
simulator's own truth (``/sim/truth``) is never fitted to (a real rig has
none); it only gives the recorded outcome.

Where the run started (the arm's joints, the target's placement and its
initial glide) is the recording's own: from its scene (``scene_json``) when
a simulator made it, else the arm's first measured joints (:data:`START_KEYS`).
Every scene key that is neither a start key, a fittable key
(:mod:`ffexp.calibrate.params`) nor the sensor's noise must equal the base
scene's: a recording of another scene is bad input, named by its first
differing key.
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from drivers import registry
from drivers.base.backend import RobotBackend
from drivers.description.scene import Scene
from drivers.rig import validate_rig
from ffexp.errors import InputError
from ffexp.recording import Recording, load
from ffexp.recording.batch import missing_topic
from ffexp.sweeps.keys import toml_text

#: Topics read from a recording besides the applied commands' (its robot's back-end names
#: those: :class:`drivers.base.backend.CommandFields`).
TOPICS = ("/robot/state", "/ft/raw", "/target/pose", "/task/funnel")
#: Scene keys that say where a run started: taken from each recording's own scene.
START_KEYS = ("arm.q_init", "arm.base_pos", "target.distance", "target.lateral",
              "target.yaw_deg", "target.velocity", "seed")
#: Scene keys of noise and chance: the replay is noise-free, they may differ freely.
NOISE_KEYS = ("ft_sensor.noise_std", "ft_sensor.bias_std", "ft_sensor.drift_density")
#: Fewest cycles worth replaying (0.5 s at 200 Hz).
MIN_CYCLES = 100


@dataclass(frozen=True)
class ReplayInput:
    """One recording, ready to replay: the commands and the measurements to compare."""

    path: Path
    cycle_s: float
    start_cycles: int
    """Cycles before the robot first commanded (the link's MON phase)."""
    commanding: np.ndarray
    """(n,) bool: the robot applied the recorded command in that cycle."""
    held: np.ndarray
    """(n,) bool: the runner sent no command in that cycle, the robot held on its own
    (replayed as ``send(None)``; never, for a robot whose commands say no such thing)."""
    pose: np.ndarray
    """(n, 4, 4) applied set-points [m]."""
    stiffness: np.ndarray
    """(n, 6) [N/m, N m/rad]."""
    damping: np.ndarray
    """(n, 6) normalised."""
    wrench: np.ndarray
    """(n, 6) superposed wrench, TCF [N, N m]."""
    t_s: np.ndarray
    """(n,) run time of each cycle [s]."""
    tcp: np.ndarray
    """(n, 3) measured TCP position [m]."""
    joints: np.ndarray
    """(n, arm's joints) measured joints [rad]."""
    ft_t_s: np.ndarray
    """(m,) run time of each F/T sample [s]."""
    ft: np.ndarray
    """(m, 6) raw F/T samples (bias and tool load included) [N, N m]."""
    target_t_s: np.ndarray
    """(k,) run time at which each valid tracked pose was true [s] (empty: no tracker)."""
    target: np.ndarray
    """(k, 3) tracked target ``[x, y, yaw]`` in the base frame [m, m, rad]."""
    start_overrides: tuple[str, ...]
    """Scene overrides that put the simulator at this recording's start."""
    robot: str
    """The simulated robot (its ``[robot] type``) that replays it."""
    sim_cycle_s: float
    """That robot's control cycle in the base scene [s]."""
    ft_type: str
    """The rig's F/T back-end as the simulator replays it (the simulated robot's default
    sensor, or the robot's own estimate)."""
    ft_settings: dict[str, Any]
    """The recorded ``[ft]`` table's other fields when it is the robot's own estimate
    (the source the UR's wrench is read from), else none."""
    robot_settings: dict[str, Any]
    """The recorded ``[robot]`` table's fields the replaying robot takes over
    (:attr:`drivers.base.backend.Replay.settings`)."""
    ft_estimate: bool
    """The F/T is the robot's own estimate: one sample a cycle, no sensor path to delay."""
    wire_precision: bool
    """The commands crossed a float32 wire (FRI's, or a sim rig at wire precision)."""
    seed: int
    scene: dict[str, Any] | None
    """The recording's scene (a simulator's run), else ``None``."""
    truth_seated: bool | None
    """The simulator's last seated flag (``None``: no truth)."""

    @property
    def name(self) -> str:
        return self.path.name

    @property
    def cycles(self) -> int:
        return int(self.t_s.shape[0])


def flatten(tree: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """``{"a": {"b": 1}}`` as ``{"a.b": 1}`` (lists are values)."""
    out: dict[str, Any] = {}
    for key, value in tree.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out.update(flatten(value, f"{name}."))
        else:
            out[name] = value
    return out


def override(key: str, value: Any) -> str:
    """``key=value`` with the value as TOML (what ``--set`` parses)."""
    return f"{key}={toml_text(value)}"


def _meta(rec: Recording) -> dict[str, str]:
    return rec.metadata.get("run", {})


def _json(rec: Recording, key: str) -> dict[str, Any] | None:
    text = _meta(rec).get(key)
    if not text:
        return None
    try:
        data = json.loads(text)
    except json.JSONDecodeError:
        raise InputError(f"{rec.path}: metadata {key} is not JSON") from None
    return data if isinstance(data, dict) else None


def default_robot() -> RobotBackend[Any]:
    """The robot of the default rig (the simulator's): what a recording without its driver
    named was made with, and what the base scene is built for."""
    return registry.robot_backend(validate_rig({}, "<calibration replay>").robot.type)


def replayer(path: Path, driver: str) -> RobotBackend[Any]:
    """The simulated robot that replays recordings of ``driver`` (a recording's robot type;
    empty: the default rig's), else :class:`InputError`."""
    if not driver and default_robot().replay is not None:
        return default_robot()
    found = registry.replayer(driver)
    if found is None:
        can = sorted({t for r in registry.robot_types()
                      if (rep := registry.robot_backend(r).replay) is not None
                      for t in rep.robots})
        raise InputError(f"{path}: recorded with robot driver {driver!r}; the simulator "
                         f"replays recordings of robot types {', '.join(can)}")
    return found


def _driver(path: Path) -> str:
    """A recording's robot type (``driver`` of its run metadata; empty: not named)."""
    meta = load(path, ()).metadata.get("run", {})
    return meta.get("driver", "")


def replaying_robot(paths: Sequence[Path]) -> RobotBackend[Any]:
    """The one simulated robot that replays every recording of ``paths`` (the first's
    if none is given), else :class:`InputError` naming the recording that needs another."""
    found: RobotBackend[Any] | None = None
    first: Path | None = None
    for path in paths:
        robot = replayer(path, _driver(path))
        if found is None:
            found, first = robot, path
        elif robot.rig_type != found.rig_type:
            raise InputError(f"{path}: replayed by the {robot.rig_type} robot, {first} by the "
                             f"{found.rig_type} robot: calibrate recordings of one robot "
                             "family at a time")
    return found if found is not None else default_robot()


def _command_topics() -> tuple[str, ...]:
    """Where the replayable robots' recordings hold their applied commands."""
    return tuple(dict.fromkeys(
        rep.commands.topic for r in registry.robot_types()
        if (rep := registry.robot_backend(r).replay) is not None))


def _need(rec: Recording, topic: str, why: str) -> None:
    data = rec.topics.get(topic)
    if data is None or len(data) == 0:
        raise InputError(f"{rec.path}: no {topic} in this recording: {why}")


def check_scene(path: Path, scene: Mapping[str, Any], base: Mapping[str, Any],
                free: tuple[str, ...]) -> None:
    """Raise :class:`InputError` if ``scene`` differs from ``base`` in a key not in ``free``."""
    mine, theirs = flatten(scene), flatten(base)
    for key in sorted(set(mine) | set(theirs)):
        if key in free or key in START_KEYS or key in NOISE_KEYS:
            continue
        if mine.get(key) != theirs.get(key):
            raise InputError(
                f"{path}: recorded in another scene: {key} is {mine.get(key)!r}, the base scene "
                f"has {theirs.get(key)!r} (only start, noise and fitted keys may differ)")


def read_input(path: Path, base_scene: Mapping[str, Any], free: tuple[str, ...]) -> ReplayInput:
    """Load and check one recording for replay (:class:`InputError` on anything unusable).

    Args:
        path: the recording.
        base_scene: the scene the simulator replays in (its JSON form).
        free: scene keys allowed to differ from the base scene (the fitted ones,
            and every fittable key: the rig's own values are what is unknown).
    """
    rec = load(path, (*TOPICS, *_command_topics()))
    if not rec.complete:
        raise InputError(f"{path}: recording is incomplete (a killed run or a truncated file); "
                         "`ffexp recover` rewrites it, calibration needs whole runs")
    meta = _meta(rec)
    driver = meta.get("driver", "")
    sim = replayer(path, driver)
    replay = sim.replay
    assert replay is not None  # (what registry.replayer finds)
    cmd_fields = replay.commands
    lean = missing_topic(path, rec.metadata, rec.topics, (cmd_fields.topic, "/ft/raw"))
    if lean is not None:  # calibration replays the commands and compares the F/T samples
        raise InputError(lean)
    _need(rec, "/robot/state", "the measured states are what the replay is compared with")
    _need(rec, cmd_fields.topic, "a recording without the applied commands cannot be "
          f"replayed (the {sim.rig_type} robot replays them from there)")
    _need(rec, "/ft/raw", "the F/T samples are compared with the simulated ones")
    state, cmd = rec.topic("/robot/state"), rec.topic(cmd_fields.topic)
    n = min(len(state), len(cmd))
    n_joints = int(state["n_joints"][0])
    sim_scene = Scene.model_validate(base_scene)
    joints = sim_scene.arm.description.joints
    if n_joints != joints:
        raise InputError(f"{path}: a robot with {n_joints} joints; the simulator's arm is the "
                         f"{joints}-joint {sim_scene.arm.description.name}")
    if n < MIN_CYCLES:
        raise InputError(f"{path}: {n} cycles; calibration needs at least {MIN_CYCLES}")
    commanding = state["commanding"][:n].astype(bool)
    held = np.zeros(n, dtype=bool)
    if cmd_fields.held:
        held = (cmd[cmd_fields.held][:n].astype(np.int64) & cmd_fields.held_flag) != 0
    if not commanding.any():
        raise InputError(f"{path}: the robot never commanded; nothing to replay")
    start_cycles = int(np.argmax(commanding))
    cycle_s = float(state["cycle_s"][0])
    scene_cycle = replay.cycle_s(sim_scene)
    if abs(cycle_s - scene_cycle) > 1e-6:
        raise InputError(f"{path}: recorded at a {cycle_s * 1e3:g} ms cycle; the base scene's "
                         f"control cycle is {scene_cycle * 1e3:g} ms")
    t0 = rec.run_start_ns
    scene = _json(rec, "scene_json")  # a simulator's run
    if scene is not None:
        check_scene(path, scene, base_scene, free)
        flat = flatten(scene)
        starts = tuple(override(k, flat[k]) for k in START_KEYS if k in flat)
    else:
        q0 = [float(v) for v in state["joint_pos"][0]]
        starts = (override("arm.q_init", q0),)
    recorded_ft = meta.get("ft", "")
    estimate = recorded_ft in replay.estimate_ft
    rig = _json(rec, "rig_json") or {}
    robot_table, ft_table = rig.get("robot") or {}, rig.get("ft") or {}
    robot_settings = {k: robot_table[k] for k in replay.settings if k in robot_table}
    ft_settings = {k: v for k, v in ft_table.items() if k != "type"} \
        if estimate and ft_table.get("type") == recorded_ft else {}
    ft_type = recorded_ft if estimate else sim.default_ft
    wire = driver in replay.wire or meta.get("wire_precision") == "true"
    pose = cmd[cmd_fields.pose][:n].reshape(n, 4, 4)
    ft = rec.topic("/ft/raw")
    tracked_t, tracked = _target(rec, int(state["time_ns"][0]))  # the robot's clock
    placed = rec.topics.get("/task/funnel")  # the funnel's placement by the truth
    seated = bool(placed["within"][-1]) if placed is not None and len(placed) else None
    return ReplayInput(
        path=path, cycle_s=cycle_s, start_cycles=start_cycles, commanding=commanding,
        held=held,
        pose=pose.astype(np.float64),
        stiffness=cmd[cmd_fields.stiffness][:n].astype(np.float64),
        damping=cmd[cmd_fields.damping][:n].astype(np.float64),
        wrench=cmd[cmd_fields.wrench][:n].astype(np.float64),
        t_s=(state.log_time_ns[:n] - t0) / 1e9,
        tcp=state["tcp_pose"][:n].reshape(n, 4, 4)[:, :3, 3].astype(np.float64),
        joints=state["joint_pos"][:n, :n_joints].astype(np.float64),
        ft_t_s=(ft.log_time_ns - t0) / 1e9, ft=ft["wrench"].astype(np.float64),
        target_t_s=tracked_t, target=tracked, start_overrides=starts, robot=sim.rig_type,
        sim_cycle_s=scene_cycle, ft_type=ft_type, ft_settings=ft_settings,
        robot_settings=robot_settings, ft_estimate=estimate, wire_precision=wire,
        seed=int(meta.get("seed", "0") or 0), scene=scene,
        truth_seated=seated,
    )


def _target(rec: Recording, t0: int) -> tuple[np.ndarray, np.ndarray]:
    """Valid tracked poses, their times from ``t0`` on the robot's clock (the tracker's)."""
    data = rec.topics.get("/target/pose")
    if data is None or len(data) == 0:
        return np.zeros(0), np.zeros((0, 3))
    ok = data["valid"].astype(bool)
    pose = data["pose"][ok].reshape(-1, 4, 4)
    xy_yaw = np.column_stack([pose[:, 0, 3], pose[:, 1, 3],
                              np.arctan2(pose[:, 1, 0], pose[:, 0, 0])])
    return (data["time_ns"][ok] - t0) / 1e9, xy_yaw


def read_inputs(paths: list[Path], base_scene: Mapping[str, Any],
                free: tuple[str, ...]) -> Iterator[ReplayInput]:
    """:func:`read_input` of each path, in order."""
    for path in paths:
        yield read_input(path, base_scene, free)
