"""Rig files (``rigs/*.toml``): which robot and F/T back-ends a run uses, and every hardware number.

A rig has two tables, each discriminated by ``type``::

    [robot]
    type = "fri1"            # "sim" | "fri1" | "mock"
    robot_ip = "192.168.0.20"
    port = 49938

    [ft]
    type = "netft"           # "sim" | "netft" | "fri-estimate" | "mock"
    host = "192.168.1.1"

An optional third table names the target tracker (default ``"none"``)::

    [tracker]
    type = "camera"          # "none" | "sim" | "camera"
    source = "http://127.0.0.1:8080/stream.mjpg"   # device index, file or URL
    calibration = "camera-calibration.toml"

Addresses, ports, counts per unit, timeouts, the answer deadline and the
cycle limits live here; command-line flags only override these fields
(``robot.port=49939``). Errors name the file and the field
(``rigs/lwr4-lab.toml: robot.port: ...``). Cross-checks: the simulated sensor
only with the simulated robot; the F/T estimate only with an FRI robot.

Pure configuration: building devices from a rig is :mod:`drivers.factory`.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import Field, model_validator

from drivers.base.types import Vec3, Vec6
from drivers.config import StrictModel, apply_overrides, read_toml, validate
from drivers.errors import ConfigError

__all__ = [
    "CameraTrackerConfig",
    "FriEstimateFt",
    "FriRobotConfig",
    "MockFt",
    "MockRobotConfig",
    "NetFtConfig",
    "NoTracker",
    "Rig",
    "SimFt",
    "SimRobotConfig",
    "SimTrackerConfig",
    "TrackerConfig",
    "default_rig",
    "load_rig",
    "validate_rig",
]

_TAGS = {"robot": ("sim", "fri1", "mock"), "ft": ("sim", "netft", "fri-estimate", "mock"),
         "tracker": ("none", "sim", "camera")}

Port = Annotated[int, Field(ge=0, le=65535)]
PosFloat = Annotated[float, Field(gt=0.0)]
NonNeg = Annotated[float, Field(ge=0.0)]


class SimRobotConfig(StrictModel):
    """The simulated LWR4+ in-process (lockstep, no sockets)."""

    type: Literal["sim"] = "sim"
    start_cycles: Annotated[int, Field(ge=0)] = 100
    """Answered cycles before the link enters command mode (a friStart script: 100)."""
    max_consecutive_misses: Annotated[int, Field(ge=1)] = 5
    """Cycles without an answer in a row that end command mode."""
    scene_file: Path | None = None
    """Scene TOML (relative to the rig file); default: the protocol's scene."""
    wire_precision: bool = False
    """Round the measurement and the command through the FRI codec, as the UDP link
    does: with ``ft.type = "fri-estimate"`` a run equals the same run in lockstep
    over UDP against ``ffexp emulate``, bit for bit."""


class FriRobotConfig(StrictModel):
    """A KUKA KRC2 LR over FRI 1.x (UDP): :class:`~drivers.fri.settings.FriSettings`."""

    type: Literal["fri1"] = "fri1"
    robot_ip: str
    """The KRC's address; packets from anywhere else are dropped."""
    port: Port = 49938
    """Local UDP port (``FRISOCK`` in the KRC's dlrrc.ini; 0 = any free port)."""
    bind_host: str = "0.0.0.0"
    """Local address to bind."""
    robot_port: Annotated[int, Field(ge=1, le=65535)] | None = None
    """If set, also require this source port."""
    answer_deadline_cycles: NonNeg = 0.5
    """Latest answer, in cycles after the packet arrived; 0 answers on arrival."""
    follow_lockstep_marker: bool = True
    """Wait for the runner when the emulator says lockstep."""
    connect_timeout_s: PosFloat = 10.0
    cycle_timeout_s: PosFloat = 1.0
    runner_timeout_s: PosFloat = 5.0
    poll_s: PosFloat = 0.05
    restart_seq_jump: Annotated[int, Field(ge=1)] = 100
    min_cycle_s: PosFloat = 0.0009
    """Shortest plausible cycle (friOpen takes 1..100 ms)."""
    max_cycle_s: PosFloat = 0.101
    """Longest plausible cycle."""


class MockRobotConfig(StrictModel):
    """A scripted stationary robot: the same state every cycle, commands recorded, no motion."""

    type: Literal["mock"] = "mock"
    cycles: Annotated[int, Field(ge=1)] = 2000
    """Cycles before the script ends."""
    cycle_s: Annotated[float, Field(ge=0.0005, le=0.1)] = 0.005
    tcp_position_m: Vec3 = (0.65, 0.0, 0.5)
    """TCP position in the base frame [m]."""
    tcp_rpy_rad: Vec3 = (0.0, 1.5707963267948966, 0.0)
    """TCP orientation, roll-pitch-yaw (fixed axes x, y, z) [rad]; default: tool Z along base X."""
    joint_pos_rad: tuple[float, ...] = (0.0, -0.3533, 0.0, 1.714, 0.0, 0.4965, 0.0)
    commanding: bool = True
    """The link reports command mode from the first cycle."""


class SimFt(StrictModel):
    """The simulated Mini45 of the sim robot's world."""

    type: Literal["sim"] = "sim"


class NetFtConfig(StrictModel):
    """An ATI Net F/T box (RDT over UDP): :class:`~drivers.netft.client.NetFtSettings`."""

    type: Literal["netft"] = "netft"
    host: str | None = None
    """The box's address; default: the FRI robot's address (``ffexp emulate`` serves both)."""
    port: Annotated[int, Field(ge=1, le=65535)] = 49152
    counts_per_force: PosFloat = 1_000_000.0
    counts_per_torque: PosFloat = 1_000_000.0
    force_unit_n: PosFloat = 1.0
    torque_unit_nm: PosFloat = 1.0
    sample_rate_hz: PosFloat = 1000.0
    mode: Literal["realtime", "buffered"] = "realtime"
    local_host: str = "0.0.0.0"
    local_port: Port = 0
    reanchor_s: PosFloat = 0.1
    resend_s: PosFloat = 0.05


class FriEstimateFt(StrictModel):
    """The KRC's own estimate of the external wrench (``estExtTcpFT``), one sample per cycle."""

    type: Literal["fri-estimate"] = "fri-estimate"


class MockFt(StrictModel):
    """A constant wrench plus seeded Gaussian noise at a fixed rate."""

    type: Literal["mock"] = "mock"
    wrench_n_nm: Vec6 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    noise_std: tuple[float, float] = (0.03, 0.0005)
    """White noise per sample [N, N m]."""
    rate_hz: PosFloat = 1000.0


class NoTracker(StrictModel):
    """No target tracker: the verdict comes from ground truth or the observer."""

    type: Literal["none"] = "none"


class SimTrackerConfig(StrictModel):
    """The simulated target's pose as a camera would report it (sim robot only)."""

    type: Literal["sim"] = "sim"
    rate_hz: PosFloat = 50.0
    """Frames per second (the paper's camera: 50 fps)."""
    latency_s: NonNeg = 0.03
    """From exposure to the pose being available."""
    position_noise_m: NonNeg = 0.0003
    """Standard deviation of each frame's position error, per horizontal axis [m]."""
    yaw_noise_deg: NonNeg = 0.1
    """Standard deviation of each frame's yaw error [deg]."""
    dropout: Annotated[float, Field(ge=0.0, le=1.0)] = 0.0
    """Fraction of frames without a pose (marker not found)."""


class CameraTrackerConfig(StrictModel):
    """A camera above the air bed tracking a fiducial marker on the target."""

    type: Literal["camera"] = "camera"
    source: str = "0"
    """OpenCV capture source: a device index (``"0"``), a video file or a URL
    (``http://host:port/stream.mjpg``)."""
    calibration: Path | None = None
    """Camera-to-table calibration TOML (``ffexp calibrate-camera``), relative to the rig file."""
    marker_dictionary: str = "DICT_4X4_50"
    """OpenCV ArUco/AprilTag dictionary of the marker."""
    marker_id: Annotated[int, Field(ge=0)] = 0
    marker_in_target_m: Vec3 = (0.0, 0.0, 0.025)
    """Marker centre in the target block frame [m] (default: centre of its top face)."""
    marker_yaw_deg: float = 0.0
    """Marker's x axis against the target's x axis, about the vertical [deg]."""
    mouth_in_target_m: Vec3 = (-0.125, 0.0, 0.073)
    """Target funnel's mouth centre in the target block frame [m] (the paper's
    block: mid-face of the -x side); the mouth frame is the block's, rotated not."""
    latency_s: NonNeg = 0.0
    """From exposure to the frame's arrival; subtracted from the arrival time."""
    lost_after_s: PosFloat = 1.0
    """No frame for this long: the stream is lost (an event; the capture reopens)."""
    reopen_s: PosFloat = 1.0
    """Wait between attempts to (re)open the source."""


TrackerConfig = Annotated[
    NoTracker | SimTrackerConfig | CameraTrackerConfig, Field(discriminator="type")
]


RobotConfig = Annotated[
    SimRobotConfig | FriRobotConfig | MockRobotConfig, Field(discriminator="type")
]
FtConfig = Annotated[SimFt | NetFtConfig | FriEstimateFt | MockFt, Field(discriminator="type")]


class Rig(StrictModel):
    """A robot, an F/T sensor and (optionally) a target tracker."""

    robot: RobotConfig = SimRobotConfig()
    ft: FtConfig = SimFt()
    tracker: TrackerConfig = NoTracker()

    @model_validator(mode="after")
    def _pairs(self) -> Rig:
        if isinstance(self.ft, SimFt) and not isinstance(self.robot, SimRobotConfig):
            raise ValueError(
                "ft.type 'sim' needs robot.type 'sim' (with an FRI robot the simulated sensor "
                "is served by the emulator: use 'netft')"
            )
        if isinstance(self.ft, FriEstimateFt) and not isinstance(
                self.robot, FriRobotConfig | SimRobotConfig):
            raise ValueError("ft.type 'fri-estimate' needs robot.type 'fri1' or 'sim'")
        if (isinstance(self.ft, NetFtConfig) and self.ft.host is None
                and not isinstance(self.robot, FriRobotConfig)):
            raise ValueError("ft.host is required unless robot.type is 'fri1'")
        if isinstance(self.tracker, SimTrackerConfig) and not isinstance(
                self.robot, SimRobotConfig):
            raise ValueError("tracker.type 'sim' needs robot.type 'sim' (over FRI the emulator "
                             "serves a camera stream: use 'camera')")
        return self


def load_rig(path: Path, overrides: Iterable[str] = ()) -> Rig:
    """Read a rig file, apply ``dotted.key=value`` overrides, validate.

    A relative ``robot.scene_file`` is taken relative to the rig file.

    Raises:
        ConfigError: ``"<path>: <field>: <message>"``.
    """
    raw = read_toml(path)
    if not raw:  # an empty file is not a rig (it would silently be the built-in sim rig)
        raise ConfigError(str(path), "", "empty rig file: a rig names its devices, "
                          '[robot] type = "sim" | "fri1" | "mock" and [ft] type = ...')
    data = apply_overrides(raw, overrides)
    rig = validate_rig(data, str(path))
    robot = rig.robot
    if isinstance(robot, SimRobotConfig) and robot.scene_file is not None:
        if not robot.scene_file.is_absolute():
            robot = robot.model_copy(update={"scene_file": path.parent / robot.scene_file})
            rig = rig.model_copy(update={"robot": robot})
    tracker = rig.tracker
    if isinstance(tracker, CameraTrackerConfig) and tracker.calibration is not None:
        if not tracker.calibration.is_absolute():
            tracker = tracker.model_copy(
                update={"calibration": path.parent / tracker.calibration})
            rig = rig.model_copy(update={"tracker": tracker})
    return rig


def validate_rig(data: Mapping[str, Any], source: str) -> Rig:
    """Validate rig data; errors name ``robot.port``, not pydantic's ``robot.fri1.port``."""
    try:
        return validate(Rig, data, source)
    except ConfigError as exc:
        parts = exc.field.split(".")
        if len(parts) >= 3 and parts[1] in _TAGS.get(parts[0], ()):
            del parts[1]
            raise ConfigError(source, ".".join(parts), exc.message) from None
        raise


def default_rig() -> Rig:
    """The built-in rig: the simulated robot and its simulated sensor."""
    return Rig()
