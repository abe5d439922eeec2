"""The back-end registry: a back-end is one folder and one registry entry.

A toy back-end defined here (no ``drivers`` or ``ffexp`` file edited) and
registered for the test appears in the rig's union and JSON Schema, the
factory, the ``--driver``/``--ft`` names and the recording's topics, and a run
on it records its extras; errors name the rig's fields as the user wrote them.
"""

from __future__ import annotations

import ast
import re
import socket
import typing
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
import pytest
from pydantic import Field

from drivers import registry
from drivers.base.backend import (
    Backend,
    DeviceConfig,
    FtBackend,
    OpenContext,
    OpenedRobot,
    OpenedSensor,
    RobotBackend,
)
from drivers.base.topics import CdrTopic, FieldSpec, MessageSpec
from drivers.base.types import Extras, LinkHealth, RobotState
from drivers.errors import AddressError, ConfigError
from drivers.factory import open_devices
from drivers.rig import Rig, load_rig, validate_rig

ROOT = Path(__file__).resolve().parents[1]


# ----------------------------------------------------------------- the toy back-end
class ToyRobotConfig(DeviceConfig):
    type: Literal["toy"] = "toy"
    cycles: Annotated[int, Field(ge=1)] = 40
    reach_m: Annotated[float, Field(gt=0.0)] = 0.5


class ToyFt(DeviceConfig):
    type: Literal["toy-ft"] = "toy-ft"


@dataclass
class ToyExtras(Extras):
    reach: float = 0.0
    tick: int = 0

    def topics(self) -> tuple[str, ...]:
        return ("/toy/extra",)


TOY_TOPIC = CdrTopic("/toy/extra", MessageSpec(
    "toy_msgs/msg/Extra", (FieldSpec("reach", "float64", 1, "m"), FieldSpec("tick", "uint32"))),
    "every cycle, toy robot")


def _open_toy(cfg: ToyRobotConfig, ctx: OpenContext) -> OpenedRobot:
    from drivers.mock.driver import MockRobot

    pose = np.eye(4)
    pose[:3, 3] = (cfg.reach_m, 0.0, 0.4)
    script = [
        RobotState(time_ns=i * 5_000_000, tcp_pose_m=pose.copy(), joint_pos_rad=np.zeros(3),
                   link=LinkHealth(commanding=True, healthy=True, cycle=i, cycle_s=0.005),
                   tcp_twist_mps_radps=np.zeros(6), extras=ToyExtras(cfg.reach_m, i))
        for i in range(cfg.cycles)
    ]
    robot = MockRobot(script)
    return OpenedRobot(robot, robot.now_ns, None, {"driver": "toy", "toy_cycles": str(cfg.cycles)})


def _open_toy_ft(cfg: ToyFt, ctx: OpenContext, robot: OpenedRobot) -> OpenedSensor:
    from drivers.mock.driver import NoisyFtSensor

    return OpenedSensor(NoisyFtSensor((0.0,) * 6, (0.0, 0.0), 200.0, clock=robot.clock))


def _toy_ft_pairs(cfg: ToyFt, robot: DeviceConfig) -> str | None:
    return None if robot.type == "toy" else "ft.type 'toy-ft' needs robot.type 'toy'"


TOY = Backend(
    "toy",
    robots=(RobotBackend(ToyRobotConfig, _open_toy, driver="toy-driver", default_ft="toy-ft"),),
    sensors=(FtBackend(ToyFt, _open_toy_ft, _toy_ft_pairs),),
    topics=lambda: (TOY_TOPIC,),
)


@pytest.fixture
def toy() -> Iterator[Backend]:
    with registry.registered(TOY) as backend:
        yield backend


# ----------------------------------------------------------------- registration
def test_a_toy_back_end_joins_the_rig_union_and_its_schema(toy: Backend) -> None:
    rig = validate_rig({"robot": {"type": "toy", "reach_m": 0.7}, "ft": {"type": "toy-ft"}}, "t")
    assert isinstance(rig.robot, ToyRobotConfig) and rig.robot.reach_m == 0.7
    assert isinstance(rig.ft, ToyFt)
    assert "ToyRobotConfig" in Rig.model_json_schema()["$defs"]
    assert "toy" in registry.robot_types() and "toy-ft" in registry.ft_types()
    # its fields are checked and named as the user wrote them
    with pytest.raises(ConfigError) as info:
        validate_rig({"robot": {"type": "toy", "reach_m": -1.0}, "ft": {"type": "toy-ft"}},
                     "rigs/toy.toml")
    assert str(info.value).startswith("rigs/toy.toml: robot.reach_m: ")
    # its own pairing rule
    with pytest.raises(ConfigError, match=r"ft\.type 'toy-ft' needs robot\.type 'toy'"):
        validate_rig({"robot": {"type": "sim"}, "ft": {"type": "toy-ft"}}, "t")


def test_the_toy_leaves_no_trace_once_unregistered() -> None:
    with registry.registered(TOY):
        pass
    assert "toy" not in registry.robot_types()
    assert "ToyRobotConfig" not in Rig.model_json_schema()["$defs"]
    with pytest.raises(ConfigError, match=r"^t: robot: .*'toy'"):
        validate_rig({"robot": {"type": "toy"}}, "t")
    from ffexp.recording.topics import CDR_TOPICS

    assert "/toy/extra" not in CDR_TOPICS


def test_a_taken_name_is_refused() -> None:
    clash = Backend("clash", robots=(RobotBackend(ToyRobotConfig, _open_toy, driver="sim",
                                                  default_ft="sim"),))
    with pytest.raises(ValueError, match="--driver 'sim' is taken"):
        registry.register(clash)
    again = Backend("again", sensors=(FtBackend(ToyFt, _open_toy_ft),))
    with registry.registered(TOY), pytest.raises(ValueError, match="type 'toy-ft' is taken"):
        registry.register(again)
    assert "toy-ft" not in registry.ft_types()


def test_the_factory_opens_the_toy_and_the_driver_name_builds_its_rig(toy: Backend) -> None:
    from ffexp.experiment import load_rig_choice
    from ffexp.rig_choice import RigChoice

    assert "toy-driver" in registry.driver_names()
    rig, source = load_rig_choice(RigChoice(driver="toy-driver", overrides=("robot.cycles=3",)))
    assert source == "<built-in toy-driver rig>"
    assert (rig.robot.type, rig.ft.type) == ("toy", "toy-ft")
    dev = open_devices(rig, source=source, scene_file=Path("unused.toml"))
    try:
        assert dev.metadata["driver"] == "toy" and dev.metadata["ft"] == "toy-ft"
        assert dev.metadata["tracker"] == "none" and dev.tracker is None
        dev.robot.connect()
        states = list(dev.robot.measurements())
    finally:
        dev.close()
    assert len(states) == 3 and isinstance(states[0].extras, ToyExtras)
    names = registry.driver_names()
    assert names[:5] == ("sim", "fri", "mock", "ur", "ur-sim") and names[-1] == "toy-driver"
    with pytest.raises(ConfigError, match=r"^--driver: nope: unknown driver; choose one of "
                                          + re.escape(", ".join(names)) + "$"):
        load_rig_choice(RigChoice(driver="nope"))


def test_a_run_on_the_toy_records_its_extras_on_its_own_topic(toy: Backend,
                                                               tmp_path: Path) -> None:
    from ffexp.experiment import run_file
    from ffexp.recording import load
    from ffexp.recording.topics import CDR_TOPICS
    from ffexp.rig_choice import RigChoice

    assert CDR_TOPICS["/toy/extra"] is TOY_TOPIC
    res = run_file(ROOT / "protocols" / "method1_case1.toml", ["run.timeout_s=0.2"],
                   rig=RigChoice(driver="toy-driver", overrides=("robot.reach_m=0.6",)),
                   out_dir=tmp_path)
    rec = load(res.path)
    extra = rec.topic("/toy/extra")
    assert len(extra) == 40  # one per cycle the toy robot reported
    np.testing.assert_array_equal(extra["tick"], np.arange(40))
    np.testing.assert_array_equal(extra["reach"], 0.6)
    assert rec.metadata["run"]["driver"] == "toy"


# ----------------------------------------------------------------- the shipped back-ends
def test_each_driver_takes_its_rig_table_as_is() -> None:
    """No second settings class: the FRI and Net F/T drivers take the rig's models."""
    from drivers.fri.backend import FriRobotConfig
    from drivers.fri.driver import FriRobot
    from drivers.netft.backend import NetFtConfig
    from drivers.netft.client import NetFtClient

    assert typing.get_type_hints(FriRobot.__init__)["settings"] is FriRobotConfig
    assert typing.get_type_hints(NetFtClient.__init__)["settings"] is NetFtConfig
    assert registry.robot_backend("fri1").config is FriRobotConfig
    assert registry.ft_backend("netft").config is NetFtConfig


def test_no_settings_class_or_renaming_table_is_left() -> None:
    """The acceptance's grep: no ``*Settings`` class in the FRI or Net F/T back-end, and no
    table renaming rig fields in the factory."""
    for folder in ("fri", "netft"):
        for path in (ROOT / "drivers" / folder).glob("*.py"):
            tree = ast.parse(path.read_text())
            names = [n.name for n in ast.walk(tree) if isinstance(n, ast.ClassDef)]
            assert not [n for n in names if n.endswith("Settings")], path
    factory = (ROOT / "drivers" / "factory.py").read_text()
    assert "_FRI_FIELDS" not in factory and "local_port" not in factory


def _busy_port() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    return s


@pytest.mark.parametrize(
    ("robot", "ft", "field"),
    [
        ({"robot_ip": "10.0.0"}, {}, "robot.robot_ip"),
        ({"robot_ip": "127.0.0.1", "bind_host": "127.0.0.1", "port": "BUSY"}, {}, "robot.port"),
        ({"robot_ip": "127.0.0.1", "bind_host": "127.0.0.1", "port": 0},
         {"host": "999.1.1.1"}, "ft.host"),
        ({"robot_ip": "127.0.0.1", "bind_host": "127.0.0.1", "port": 0},
         {"local_host": "127.0.0.1", "local_port": "BUSY"}, "ft.local_port"),
    ],
)
def test_device_errors_name_the_rig_field_as_written(
    tmp_path: Path, robot: dict[str, object], ft: dict[str, object], field: str
) -> None:
    busy = _busy_port()
    port = busy.getsockname()[1]
    try:
        def fill(table: dict[str, object]) -> str:
            return "".join(f"{k} = {port if v == 'BUSY' else repr(v).replace(chr(39), chr(34))}\n"
                           for k, v in table.items())

        path = tmp_path / "lab.toml"
        path.write_text(f'[robot]\ntype = "fri1"\n{fill(robot)}[ft]\ntype = "netft"\n{fill(ft)}')
        with pytest.raises(AddressError) as info:
            open_devices(load_rig(path), source=str(path), scene_file=Path("unused.toml"))
    finally:
        busy.close()
    assert str(info.value).startswith(f"{path}: {field}: ")
    assert "\n" not in str(info.value)


def test_the_netft_host_defaults_to_the_robot_and_is_named_when_missing() -> None:
    from drivers.netft.backend import NetFtConfig
    from drivers.netft.client import NetFtClient

    client = NetFtClient(NetFtConfig(), default_host="127.0.0.1", where="r.toml: ft")
    assert client.addr == ("127.0.0.1", 49152)
    with pytest.raises(ConfigError, match=r"^r\.toml: ft\.host: required"):
        NetFtClient(NetFtConfig(), where="r.toml: ft")


def test_a_path_field_of_any_table_is_relative_to_the_rig_file(tmp_path: Path) -> None:
    path = tmp_path / "r.toml"
    path.write_text('[robot]\ntype = "sim"\nscene_file = "s.toml"\n'
                    '[tracker]\ntype = "camera"\ncalibration = "/abs/cal.toml"\n')
    from drivers.camera.backend import CameraTrackerConfig
    from drivers.fri.config import SimRobotConfig

    rig = load_rig(path)
    assert isinstance(rig.robot, SimRobotConfig) and isinstance(rig.tracker, CameraTrackerConfig)
    assert rig.robot.scene_file == tmp_path / "s.toml"
    assert rig.tracker.calibration == Path("/abs/cal.toml")
