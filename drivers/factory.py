"""Devices from a rig (:mod:`drivers.rig`): the robot, F/T sensor and target tracker a run uses.

:func:`open_devices` imports each back-end only when the rig uses it, binds
the FRI port at once (a port in use is reported before anything is
recorded) and describes the devices for the recording (``metadata``,
``attachments``) and for the user (``notice``). Errors name the rig file and
field (``rigs/lwr4-lab.toml: robot.port: ...``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from drivers.base.interfaces import ForceTorqueSensor, RobotDriver, TargetTracker
from drivers.errors import AddressError, ConfigError
from drivers.rig import (
    CameraTrackerConfig,
    FriEstimateFt,
    FriRobotConfig,
    MockFt,
    MockRobotConfig,
    NetFtConfig,
    Rig,
    SimFt,
    SimRobotConfig,
    SimTrackerConfig,
)

__all__ = ["Devices", "open_devices"]


@dataclass
class Devices:
    """An opened robot and sensor, with what the recording says about them."""

    robot: RobotDriver
    sensor: ForceTorqueSensor
    metadata: dict[str, str] = field(default_factory=dict)
    """Run metadata: driver name, scene file and JSON, addresses, ..."""
    attachments: list[tuple[str, bytes]] = field(default_factory=list)
    """Files to attach to the recording (name, bytes): the scene TOML for the sim."""
    notice: str | None = None
    """One line for the user about the devices (where a link listens), or ``None``."""
    tracker: TargetTracker | None = None
    """The target tracker, when the rig has one."""

    def close(self) -> None:
        """Stop the tracker and the sensor and close the robot; idempotent."""
        try:
            if self.tracker is not None:
                self.tracker.stop()
        finally:
            try:
                self.sensor.stop()
            finally:
                self.robot.close()


def _rpy_pose(position: Sequence[float], rpy: Sequence[float]) -> np.ndarray:
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), \
        math.sin(y)
    pose = np.eye(4)
    pose[:3, :3] = [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]
    pose[:3, 3] = position
    return pose


def open_devices(
    rig: Rig,
    *,
    source: str,
    scene_file: Path,
    scene_overrides: Sequence[str] = (),
    seed: int = 0,
) -> Devices:
    """Build (and, for UDP links, bind) the rig's robot and sensor.

    Args:
        rig: the validated rig.
        source: the rig file (or ``"<default rig>"``), named in error messages.
        scene_file: the protocol's scene, used unless the sim rig names its own.
        scene_overrides: ``dotted.key=value`` overrides of the scene.
        seed: the run's seed (world and mock noise).
    """
    robot_cfg, ft_cfg = rig.robot, rig.ft
    if isinstance(robot_cfg, SimRobotConfig):
        devices = _open_sim(robot_cfg, ft_cfg, source, scene_file, scene_overrides, seed, rig)
    elif isinstance(robot_cfg, FriRobotConfig):
        devices = _open_fri(robot_cfg, ft_cfg, source, seed)
    else:
        devices = _open_mock(robot_cfg, ft_cfg, source, seed)
    cam = rig.tracker
    if isinstance(cam, CameraTrackerConfig):
        try:
            devices.tracker = _open_camera(cam, source, devices.robot)
        except BaseException:
            devices.close()
            raise
        devices.metadata.update(tracker="camera", camera_source=cam.source)
    elif devices.tracker is None:
        devices.metadata["tracker"] = "none"
    return devices


def _open_camera(cfg: CameraTrackerConfig, source: str, robot: RobotDriver) -> TargetTracker:
    from drivers.camera import CameraTracker
    from drivers.vision import load_calibration

    if cfg.calibration is None:
        raise ConfigError(source, "tracker.calibration",
                          "a camera tracker needs a calibration file (ffexp calibrate-camera)")
    calibration = load_calibration(cfg.calibration, f"{source}: tracker.calibration")
    clock = getattr(robot, "now_ns", None)
    return CameraTracker(cfg, calibration, clock=clock, where=f"{source}: tracker.source")


def _open_sim(
    cfg: SimRobotConfig,
    ft_cfg: SimFt | NetFtConfig | FriEstimateFt | MockFt,
    source: str,
    scene_file: Path,
    scene_overrides: Sequence[str],
    seed: int,
    rig: Rig,
) -> Devices:
    from drivers.description import load_scene
    from drivers.emulate.lockstep import SimRobot
    from drivers.sim import SimFtSensor, SimWorld

    path = cfg.scene_file if cfg.scene_file is not None else scene_file
    scene = load_scene(path, scene_overrides)
    world = SimWorld(scene, seed=seed)
    robot = SimRobot(world, start_cycles=cfg.start_cycles,
                     max_consecutive_misses=cfg.max_consecutive_misses,
                     wire_precision=cfg.wire_precision)
    meta = {
        "driver": "sim",
        "scene_file": str(path),
        "scene_json": scene.model_dump_json(),
        "ft": ft_cfg.type,
        "wire_precision": str(cfg.wire_precision).lower(),
    }
    sensor: ForceTorqueSensor
    if isinstance(ft_cfg, SimFt):
        sensor = SimFtSensor(world)
    elif isinstance(ft_cfg, FriEstimateFt):  # the in-process KRC's own wrench estimate
        from drivers.fri.estimate import FriEstimateSensor

        sensor = FriEstimateSensor(robot)
    else:
        sensor = _other_sensor(ft_cfg, source, seed, lambda: world.cycle * world.cycle_ns, None)
    tracker: TargetTracker | None = None
    cam = rig.tracker
    if isinstance(cam, SimTrackerConfig):
        from drivers.sim.tracker import SimTracker

        tracker = SimTracker(world, lambda: world.cycle * world.cycle_ns, rate_hz=cam.rate_hz,
                             latency_s=cam.latency_s, position_noise_m=cam.position_noise_m,
                             yaw_noise_deg=cam.yaw_noise_deg, dropout=cam.dropout, seed=seed)
        meta["tracker"] = "sim"
    return Devices(robot, sensor, meta, [(path.name, path.read_bytes())], None, tracker)


#: Rig fields of the fri1 robot whose FriSettings field has another name.
_FRI_FIELDS = {"port": "local_port", "bind_host": "local_host"}


def _open_fri(
    cfg: FriRobotConfig,
    ft_cfg: SimFt | NetFtConfig | FriEstimateFt | MockFt,
    source: str,
    seed: int,
) -> Devices:
    from drivers.fri.driver import FriRobot
    from drivers.fri.settings import FriSettings

    settings = FriSettings(
        robot_ip=cfg.robot_ip,
        local_port=cfg.port,
        local_host=cfg.bind_host,
        robot_port=cfg.robot_port,
        answer_deadline_cycles=cfg.answer_deadline_cycles,
        follow_lockstep_marker=cfg.follow_lockstep_marker,
        connect_timeout_s=cfg.connect_timeout_s,
        cycle_timeout_s=cfg.cycle_timeout_s,
        runner_timeout_s=cfg.runner_timeout_s,
        poll_s=cfg.poll_s,
        restart_seq_jump=cfg.restart_seq_jump,
        min_cycle_s=cfg.min_cycle_s,
        max_cycle_s=cfg.max_cycle_s,
        source=f"{source}: robot",
    )
    robot = FriRobot(settings)
    try:
        try:
            host, port = robot.bind()
        except AddressError as exc:  # name the rig's field, not the settings' one
            where = exc.where
            for ours, theirs in _FRI_FIELDS.items():
                where = where.replace(f": robot.{theirs}", f": robot.{ours}")
            raise AddressError(where, exc.address, exc.message) from None
        meta = {"driver": "fri1", "robot_ip": robot.robot_ip, "fri_port": str(port),
                "ft": ft_cfg.type}
        sensor: ForceTorqueSensor
        if isinstance(ft_cfg, FriEstimateFt):
            from drivers.fri.estimate import FriEstimateSensor

            sensor = FriEstimateSensor(robot)
            where = "F/T from estExtTcpFT"
        else:
            sensor = _other_sensor(ft_cfg, source, seed, robot.now_ns, robot.robot_ip)
            where = f"F/T: {ft_cfg.type}"
            if "netft" in (meta_ft := _sensor_meta(sensor)):
                meta["netft"] = meta_ft["netft"]
                where = f"Net F/T at {meta_ft['netft']}"
    except BaseException:
        robot.close()
        raise
    notice = f"fri: listening on {host}:{port} for the KRC at {robot.robot_ip}; {where}"
    return Devices(robot, sensor, meta, [], notice)


def _open_mock(
    cfg: MockRobotConfig,
    ft_cfg: SimFt | NetFtConfig | FriEstimateFt | MockFt,
    source: str,
    seed: int,
) -> Devices:
    from drivers.mock import stationary_robot

    robot = stationary_robot(
        cfg.cycles, cfg.cycle_s, _rpy_pose(cfg.tcp_position_m, cfg.tcp_rpy_rad),
        cfg.joint_pos_rad, cfg.commanding,
    )
    sensor = _other_sensor(ft_cfg, source, seed, robot.now_ns, None)
    meta = {"driver": "mock", "ft": ft_cfg.type, "mock_cycles": str(cfg.cycles)}
    meta.update(_sensor_meta(sensor))
    return Devices(robot, sensor, meta, [], None)


def _other_sensor(
    cfg: SimFt | NetFtConfig | FriEstimateFt | MockFt,
    source: str,
    seed: int,
    clk: Callable[[], int | None],
    robot_host: str | None,
) -> ForceTorqueSensor:
    """A mock or Net F/T sensor (the pairs the rig allows)."""
    if isinstance(cfg, MockFt):
        from drivers.mock import NoisyFtSensor

        return NoisyFtSensor(cfg.wrench_n_nm, cfg.noise_std, cfg.rate_hz, seed=seed, clock=clk)
    if isinstance(cfg, NetFtConfig):
        from drivers.netft.client import NetFtClient, NetFtSettings

        host = cfg.host if cfg.host is not None else robot_host
        if host is None:  # the rig's cross-check makes this unreachable
            raise ValueError("Net F/T host unknown")
        client = NetFtClient(
            NetFtSettings(
                host=host, port=cfg.port, counts_per_force=cfg.counts_per_force,
                counts_per_torque=cfg.counts_per_torque, force_unit_n=cfg.force_unit_n,
                torque_unit_nm=cfg.torque_unit_nm, sample_rate_hz=cfg.sample_rate_hz,
                mode=cfg.mode, local_host=cfg.local_host, local_port=cfg.local_port,
                reanchor_s=cfg.reanchor_s, resend_s=cfg.resend_s, source=f"{source}: ft",
            ),
            clock=clk,
        )
        client.open()
        return client
    raise ValueError(f"ft.type {cfg.type!r} is not available with this robot")


def _sensor_meta(sensor: ForceTorqueSensor) -> dict[str, str]:
    addr = getattr(sensor, "addr", None)
    if isinstance(addr, tuple) and len(addr) == 2:
        return {"netft": f"{addr[0]}:{addr[1]}"}
    return {}
