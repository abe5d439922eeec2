"""Rig files and the device factory."""

from __future__ import annotations

import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from drivers.base import ApplyStatus, CartesianCommand, ForceTorqueSensor, RobotDriver
from drivers.errors import AddressError, ConfigError
from drivers.factory import open_devices
from drivers.fri.backend import FriRobotConfig
from drivers.fri.config import SimRobotConfig
from drivers.mock.backend import MockRobotConfig
from drivers.netft.backend import NetFtConfig
from drivers.rig import Rig, default_rig, load_rig

RIGS = Path(__file__).resolve().parent.parent / "rigs"


@pytest.mark.parametrize("name", ["sim", "mock", "emulator", "emulator-camera", "lwr4-lab"])
def test_each_rig_file_loads(name: str) -> None:
    rig = load_rig(RIGS / f"{name}.toml")
    assert rig.robot.type == {"sim": "sim", "mock": "mock"}.get(name, "fri1")


def test_emulator_rig_matches_ffexp_emulate() -> None:
    rig = load_rig(RIGS / "emulator.toml")
    assert isinstance(rig.robot, FriRobotConfig) and isinstance(rig.ft, NetFtConfig)
    assert (rig.robot.robot_ip, rig.robot.port) == ("127.0.0.1", 49938)
    assert (rig.ft.host, rig.ft.port) == ("127.0.0.1", 49152)


def test_default_rig_is_sim_and_sim() -> None:
    rig = default_rig()
    assert isinstance(rig.robot, SimRobotConfig) and rig.ft.type == "sim"
    assert rig.robot.start_cycles == 100


def write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "r.toml"
    p.write_text(text)
    return p


@pytest.mark.parametrize(
    ("text", "field", "message"),
    [
        ('[robot]\ntype = "fri1"\nrobot_ip = "1.2.3.4"\nport = 70000\n[ft]\ntype = "netft"\n',
         "robot.port", "less than or equal to 65535"),
        ('[robot]\ntype = "fri1"\n[ft]\ntype = "netft"\n', "robot.robot_ip", "Field required"),
        ('[robot]\ntype = "mock"\nbogus = 1\n[ft]\ntype = "mock"\n', "robot.bogus", "unknown key"),
        ('[robot]\ntype = "sim"\n[ft]\ntype = "netft"\nhost = "h"\nport = 0\n', "ft.port",
         "greater than or equal to 1"),
        ('[robot]\ntype = "kuka"\n', "robot", "'kuka'"),
    ],
)
def test_bad_field_names_file_and_field(
    tmp_path: Path, text: str, field: str, message: str
) -> None:
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_rig(path)
    assert str(info.value).startswith(f"{path}: {field}: ")
    assert message in str(info.value)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    ("text", "needs"),
    [
        ('[robot]\ntype = "fri1"\nrobot_ip = "1.2.3.4"\n[ft]\ntype = "sim"\n', "robot.type 'sim'"),
        ('[robot]\ntype = "mock"\n[ft]\ntype = "fri-estimate"\n', "robot.type 'fri1' or 'sim'"),
        ('[robot]\ntype = "mock"\n[ft]\ntype = "netft"\n', "ft.host is required"),
        ('[robot]\ntype = "fri1"\nrobot_ip = "1.2.3.4"\n[ft]\ntype = "netft"\n'
         '[tracker]\ntype = "sim"\n', "tracker.type 'sim' needs robot.type 'sim'"),
    ],
)
def test_cross_checks(tmp_path: Path, text: str, needs: str) -> None:
    with pytest.raises(ConfigError, match=needs):
        load_rig(write(tmp_path, text))


def test_overrides_change_fields_and_name_the_file(tmp_path: Path) -> None:
    rig = load_rig(RIGS / "emulator.toml", ["robot.port=50001", "ft.port=50002"])
    assert isinstance(rig.robot, FriRobotConfig) and rig.robot.port == 50001
    with pytest.raises(ConfigError, match=r"emulator\.toml: robot\.port: "):
        load_rig(RIGS / "emulator.toml", ["robot.port=-1"])


def test_relative_scene_file_is_relative_to_the_rig(tmp_path: Path) -> None:
    rig = load_rig(write(tmp_path, '[robot]\ntype = "sim"\nscene_file = "s.toml"\n'))
    assert isinstance(rig.robot, SimRobotConfig)
    assert rig.robot.scene_file == tmp_path / "s.toml"


def test_factory_builds_sim_devices(paper_scene_path: Path) -> None:
    rig = Rig(robot=SimRobotConfig(start_cycles=0))
    dev = open_devices(rig, source="<default rig>", scene_file=paper_scene_path, seed=3)
    assert isinstance(dev.robot, RobotDriver) and isinstance(dev.sensor, ForceTorqueSensor)
    assert dev.metadata["driver"] == "sim"
    assert dev.metadata["scene_file"] == str(paper_scene_path)
    assert '"seed"' in dev.metadata["scene_json"]
    assert dev.attachments == [(paper_scene_path.name, paper_scene_path.read_bytes())]
    times, n_ft = [], []
    try:
        dev.robot.connect()
        dev.sensor.start()
        for state in dev.robot.measurements():
            times.append(state.time_ns)
            n_ft.append(len(dev.sensor.samples()))
            cmd = CartesianCommand(pose_m=state.tcp_pose_m.copy())
            assert dev.robot.send(cmd).status == ApplyStatus.APPLIED
            if len(times) == 4:
                break
    finally:
        dev.close()
        dev.close()  # idempotent
    assert times == [0, 5_000_000, 10_000_000, 15_000_000]
    assert n_ft == [0, 5, 5, 5]
    assert not dev.robot.connected and not dev.sensor.running


def test_sim_rig_scene_file_wins_and_overrides_apply(paper_scene_path: Path) -> None:
    rig = Rig(robot=SimRobotConfig(scene_file=paper_scene_path))
    dev = open_devices(rig, source="r.toml", scene_file=Path("/nonexistent.toml"),
                       scene_overrides=["fri.cycle=0.002"])
    assert '"cycle":0.002' in dev.metadata["scene_json"]
    dev.close()


def test_factory_builds_mock_devices() -> None:
    dev = open_devices(load_rig(RIGS / "mock.toml", ["robot.cycles=3"]), source="rigs/mock.toml",
                       scene_file=Path("unused.toml"), seed=1)
    assert dev.metadata["driver"] == "mock" and dev.attachments == []
    got = []
    with dev.robot, dev.sensor:
        for state in dev.robot.measurements():
            ft = dev.sensor.samples()
            got.append((state.time_ns, len(ft)))
            np.testing.assert_allclose(state.tcp_pose_m[:3, 3], [0.65, 0.0, 0.5])
            np.testing.assert_allclose(state.tcp_pose_m[:3, 2], [1.0, 0.0, 0.0], atol=1e-12)
            assert np.all(np.abs(ft.wrench) < 0.3)
            dev.robot.send(None)
    assert got == [(0, 1), (5_000_000, 5), (10_000_000, 5)]  # 1 kHz on the robot's clock


def test_mock_robot_config_defaults() -> None:
    cfg = MockRobotConfig()
    assert cfg.cycles > 0 and cfg.cycle_s == 0.005


def test_fri_rig_binds_its_port_at_once() -> None:
    busy = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    busy.bind(("127.0.0.1", 0))
    port = busy.getsockname()[1]
    try:
        rig = Rig(robot=FriRobotConfig(robot_ip="127.0.0.1", port=port, bind_host="127.0.0.1"),
                  ft=NetFtConfig(host="127.0.0.1", local_host="127.0.0.1"))
        with pytest.raises(AddressError, match=r"rigs/x\.toml: robot\.") as info:
            open_devices(rig, source="rigs/x.toml", scene_file=Path("unused.toml"))
        assert str(port) in str(info.value)
    finally:
        busy.close()


def test_fri_devices_with_the_estimate_sensor() -> None:
    rig = Rig.model_validate({
        "robot": {"type": "fri1", "robot_ip": "127.0.0.1", "port": 0, "bind_host": "127.0.0.1"},
        "ft": {"type": "fri-estimate"},
    })
    dev = open_devices(rig, source="rigs/x.toml", scene_file=Path("unused.toml"))
    try:
        assert dev.metadata["driver"] == "fri1" and dev.metadata["robot_ip"] == "127.0.0.1"
        assert int(dev.metadata["fri_port"]) > 0
        assert dev.notice is not None and "estExtTcpFT" in dev.notice
    finally:
        dev.close()


def test_sim_at_wire_precision_with_the_krc_estimate_as_the_sensor(tmp_path: Path) -> None:
    """``robot.wire_precision`` and ``ft.type = "fri-estimate"`` on the sim rig: what the
    in-process KRC reports is what float32 FRI fields can hold, and the F/T samples are
    its own wrench estimate, one per cycle (the pair that equals a run over UDP)."""
    import numpy as np

    from ffexp.experiment import run_file
    from ffexp.recording import load
    from ffexp.rig_choice import RigChoice

    res = run_file(RIGS.parent / "protocols" / "method1_case1.toml", ["run.timeout_s=0.5"],
                   rig=RigChoice(overrides=("robot.wire_precision=true",
                                            "ft.type='fri-estimate'")), out_dir=tmp_path)
    rec = load(res.path)
    assert rec.metadata["run"]["wire_precision"] == "true"
    msr = rec.topic("/robot/measurement")
    for name in ("msr_cart_pos", "msr_jnt_pos", "est_ext_tcp_ft"):
        x = msr[name]
        np.testing.assert_array_equal(x, x.astype(np.float32).astype(np.float64))
    ft = rec.topic("/ft/raw")
    assert len(ft) == len(msr)  # one sample per cycle
    np.testing.assert_array_equal(ft["wrench"], msr["est_ext_tcp_ft"])


def test_back_ends_are_imported_only_when_used(paper_scene_path: Path) -> None:
    code = (
        "import sys; from pathlib import Path; from drivers.factory import open_devices; "
        "from drivers.rig import default_rig; "
        f"open_devices(default_rig(), source='x', "
        f"scene_file=Path({str(paper_scene_path)!r})).close(); "
        "print(sorted(m for m in sys.modules if m.startswith(('drivers.fri.driver', "
        "'drivers.netft.client', 'drivers.mock.driver', 'drivers.fri.emulate.server', "
        "'drivers.camera.tracker'))))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_tracker_table_names_its_fields_and_resolves_the_calibration(tmp_path: Path) -> None:
    from drivers.camera.backend import CameraTrackerConfig
    from drivers.registry import NoTracker

    assert isinstance(default_rig().tracker, NoTracker)
    path = write(tmp_path, '[tracker]\ntype = "camera"\ncalibration = "cal.toml"\n')
    rig = load_rig(path)
    assert isinstance(rig.tracker, CameraTrackerConfig)
    assert rig.tracker.calibration == tmp_path / "cal.toml"
    with pytest.raises(ConfigError, match=r"tracker\.rate_hz: "):
        load_rig(write(tmp_path, '[tracker]\ntype = "sim"\nrate_hz = 0\n'))
    with pytest.raises(ConfigError, match=r"tracker: .*'eye'"):
        load_rig(write(tmp_path, '[tracker]\ntype = "eye"\n'))


def test_factory_opens_the_sim_tracker_and_checks_the_camera(paper_scene_path: Path) -> None:
    from drivers.camera.backend import CameraTrackerConfig
    from drivers.mock.backend import MockFt
    from drivers.sim.backend import SimTrackerConfig
    from drivers.sim.tracker import SimTracker

    dev = open_devices(Rig(tracker=SimTrackerConfig()), source="r.toml",
                       scene_file=paper_scene_path)
    try:
        assert isinstance(dev.tracker, SimTracker) and dev.metadata["tracker"] == "sim"
    finally:
        dev.close()
    rig = Rig(robot=MockRobotConfig(), ft=MockFt(), tracker=CameraTrackerConfig())
    with pytest.raises(ConfigError, match=r"r\.toml: tracker\.calibration: .*calibrate-camera"):
        open_devices(rig, source="r.toml", scene_file=paper_scene_path)


# -- two devices with ids (a carrier robot: docs/hil.md) ----------------------------------
ONE_ROBOT = [p for p in sorted(RIGS.glob("*.toml")) if "[carrier" not in p.read_text()]


@pytest.mark.parametrize("path", ONE_ROBOT, ids=lambda p: p.name)
def test_a_one_robot_rig_means_what_it_meant(path: Path) -> None:
    """No carrier, the chaser's default id, and the same tables as before ids existed."""
    rig = load_rig(path)
    assert rig.carrier is None and rig.id == "chaser"
    dumped = rig.model_dump(exclude={"id", "carrier"})
    assert set(dumped) == {"robot", "ft", "tracker"}


def test_a_rig_with_a_carrier_names_both_devices() -> None:
    rig = load_rig(RIGS / "hil-sim.toml")
    assert (rig.id, rig.robot.type, rig.ft.type) == ("chaser", "sim", "sim")
    assert rig.carrier is not None and rig.carrier.id == "carrier"
    assert (rig.carrier.robot.type, rig.carrier.ft is not None and rig.carrier.ft.type) == (
        "ur-sim", "ur-wrench")


def test_two_emulators_on_loopback_may_share_the_host_not_the_port(tmp_path: Path) -> None:
    text = ('[robot]\ntype = "fri1"\nrobot_ip = "127.0.0.1"\n[ft]\ntype = "fri-estimate"\n'
            '[carrier.robot]\ntype = "fri1"\nrobot_ip = "127.0.0.1"\nport = {port}\n'
            '[carrier.ft]\ntype = "fri-estimate"\n')
    ok = tmp_path / "ok.toml"
    ok.write_text(text.format(port=49939))
    assert load_rig(ok).carrier is not None
    bad = tmp_path / "bad.toml"
    bad.write_text(text.format(port=49938))
    with pytest.raises(ConfigError, match=r"127\.0\.0\.1:49938"):
        load_rig(bad)


def test_a_carrier_path_is_relative_to_the_rig_file(tmp_path: Path) -> None:
    (tmp_path / "sub").mkdir()
    rig_file = tmp_path / "sub" / "two.toml"
    rig_file.write_text('[robot]\ntype = "sim"\n[ft]\ntype = "sim"\n[carrier.robot]\n'
                        'type = "sim"\nscene_file = "scene.toml"\n[carrier.ft]\ntype = "sim"\n')
    rig = load_rig(rig_file)
    assert rig.carrier is not None
    assert isinstance(rig.carrier.robot, SimRobotConfig)
    assert rig.carrier.robot.scene_file == tmp_path / "sub" / "scene.toml"


def test_the_factory_refuses_a_carrier_it_cannot_drive() -> None:
    rig = load_rig(RIGS / "hil-sim.toml")
    with pytest.raises(ConfigError, match="carrier"):
        open_devices(rig, source="rigs/hil-sim.toml",
                     scene_file=RIGS.parent / "data/scenes/paper.toml")
