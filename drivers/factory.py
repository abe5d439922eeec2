"""Devices from a rig (:mod:`drivers.rig`): the robot, F/T sensor and target tracker a run uses.

:func:`open_devices` opens each table with the ``open`` of the back-end its
``type`` names (:mod:`drivers.registry`), which imports the back-end only when
the rig uses it; UDP links bind their port at once (a port in use is reported
before anything is recorded). The devices are described for the recording
(``metadata``, ``attachments``) and for the user (``notice``). Errors name the
rig file and field (``rigs/lwr4-lab.toml: robot.port: ...``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from drivers import registry
from drivers.base.backend import DeviceConfig, OpenContext
from drivers.base.interfaces import ForceTorqueSensor, RobotDriver, TargetTracker
from drivers.errors import ConfigError
from drivers.rig import Rig

if TYPE_CHECKING:
    from drivers.description.scene import Scene

__all__ = ["Devices", "open_devices", "robot_arm"]


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
    scene: Scene | None = None
    """The scene a simulated robot runs in (``None``: a real robot)."""

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


def open_devices(
    rig: Rig,
    *,
    source: str,
    scene_file: Path,
    scene_overrides: Sequence[str] = (),
    seed: int = 0,
) -> Devices:
    """Build (and, for UDP links, bind) the rig's robot, sensor and tracker.

    Args:
        rig: the validated rig.
        source: the rig file (or ``"<default rig>"``), named in error messages.
        scene_file: the protocol's scene, used unless the sim rig names its own.
        scene_overrides: ``dotted.key=value`` overrides of the scene.
        seed: the run's seed (world and mock noise).
    """
    if rig.carrier is not None:
        raise ConfigError(source, "carrier", "a run drives the chaser alone: a carrier robot "
                          "(the micro-gravity emulator) runs in `ffexp hil` only, simulated "
                          "(docs/hil.md)")
    ctx = OpenContext(source, scene_file, tuple(scene_overrides), seed)
    opened = registry.robot_backend(rig.robot.type).open(rig.robot, ctx)
    try:
        got = registry.ft_backend(rig.ft.type).open(rig.ft, ctx, opened)
    except BaseException:
        opened.robot.close()
        raise
    meta = {**opened.metadata, "ft": rig.ft.type, **got.metadata}
    notice = None
    if opened.notice is not None:
        notice = f"{opened.notice}; {got.note or f'F/T: {rig.ft.type}'}"
    devices = Devices(opened.robot, got.sensor, meta, opened.attachments, notice,
                      scene=opened.scene)
    try:
        tracked = registry.tracker_backend(rig.tracker.type).open(rig.tracker, ctx, opened)
    except BaseException:
        devices.close()
        raise
    devices.tracker = tracked.tracker
    devices.metadata.update(tracker=rig.tracker.type, **tracked.metadata)
    return devices


def robot_arm(robot: DeviceConfig) -> tuple[str | None, bool]:
    """The arm model (a scene's ``arm.model``) the rig's robot drives, and whether it puts
    that arm in the place of a scene's other arm (``None``: any arm, as the mock).

    Each robot back-end declares both (:class:`~drivers.base.backend.RobotBackend`): a
    KRC over FRI 1.x drives the LWR4+ and nothing else (its packets carry seven joints);
    a UR controller the UR5e, which it puts in an LWR4+ scene's place (the protocols'
    paper scene), as ``ffexp emulate --robot ur5e`` does.
    """
    backend = registry.robot_backend(robot.type)  # a validated rig's type is registered
    return backend.arm, backend.takes_arm_place
