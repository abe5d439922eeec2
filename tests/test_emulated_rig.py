"""The emulated rig as a library object (drivers/emulate/session.py), without the CLI."""

from __future__ import annotations

import re
import socket
from pathlib import Path

import pytest

from drivers.description.scene import Scene
from drivers.emulate.session import EmulatedRig, EmulatedRigSettings, SettingNames
from drivers.errors import AddressError, ConfigError, NotConnectedError
from drivers.fri.emulate.served import ServedKrc


def _free_port(kind: int) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _settings(**kw: object) -> EmulatedRigSettings:
    base: dict[str, object] = {
        "scene": Scene(), "remote": ("127.0.0.1", _free_port(socket.SOCK_DGRAM)),
        "host": "127.0.0.1", "port": 0, "netft_port": 0,
    }
    base.update(kw)
    return EmulatedRigSettings(**base)  # type: ignore[arg-type]


def _bindable(port: int, kind: int) -> bool:
    with socket.socket(socket.AF_INET, kind) as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
        return True


def test_it_serves_the_duration_with_nobody_answering_and_closes_everything() -> None:
    settings = _settings(pacing="realtime", duration_s=0.05)
    lines: list[str] = []
    with EmulatedRig(settings) as rig:
        assert rig.served is not None and rig.netft is not None
        krc_port, ft_port = rig.served.address[1], rig.netft.address[1]
        ready = rig.ready_line()
        stats = rig.serve(lambda: False, on_status=lines.append)
    assert ready == (f"KRC on 127.0.0.1:{krc_port} -> remote 127.0.0.1:{settings.remote[1]}, "
                     f"Net F/T on 127.0.0.1:{ft_port}, cycle 5 ms, realtime")
    assert settings.max_cycles == 10
    # at most the duration's cycles (a loaded machine may serve fewer before the duration ends),
    # every one sent and none answered
    n = stats.cycles
    assert 1 <= n <= 10 and stats.answered == 0 and stats.missed == n
    # the summary is taken at close: the KRC's last state and quality, nobody having answered
    assert re.match(rf"cycles {n}, sent {n}, answered 0, missed {n} ", rig.summary()), rig.summary()
    assert rig.summary().endswith("state MON, quality UNACCEPTABLE"), rig.summary()
    # every server is closed: their ports can be bound again
    assert _bindable(krc_port, socket.SOCK_DGRAM) and _bindable(ft_port, socket.SOCK_DGRAM)


def test_a_stop_request_ends_an_endless_serve() -> None:
    calls = []

    def stop() -> bool:
        calls.append(1)
        return True

    with EmulatedRig(_settings(pacing="lockstep", lockstep_timeout_s=0.05, netft_port=None)) as rig:
        assert rig.netft is None and "no Net F/T" in rig.ready_line()
        stats = rig.serve(stop)
    assert calls and stats.cycles == 0  # lockstep never steps before the remote answers


def test_an_error_while_serving_is_raised_in_the_callers_thread() -> None:
    with EmulatedRig(_settings(netft_port=None)) as rig:
        assert isinstance(rig.served, ServedKrc)

        def broken(**_kw: object) -> None:
            raise ConfigError("scene", "fri.cycle", "broken on purpose")

        rig.served.emulator.run = broken  # type: ignore[method-assign, assignment]
        with pytest.raises(ConfigError, match="broken on purpose"):
            rig.serve(lambda: False)


def test_a_server_that_cannot_open_closes_those_already_open(tmp_path: Path) -> None:
    """The camera's port is taken: the KRC and the Net F/T box opened before it are closed,
    and the error names the caller's field."""
    krc_port, ft_port = _free_port(socket.SOCK_DGRAM), _free_port(socket.SOCK_DGRAM)
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        settings = _settings(port=krc_port, netft_port=ft_port, camera_port=busy.getsockname()[1],
                             fields=SettingNames(camera_port="rigs/x.toml: camera.port"))
        with pytest.raises(AddressError, match=r"^rigs/x\.toml: camera\.port: 127\.0\.0\.1:"):
            EmulatedRig(settings).__enter__()
    assert _bindable(krc_port, socket.SOCK_DGRAM) and _bindable(ft_port, socket.SOCK_DGRAM)


def test_an_unwritable_calibration_names_its_field(tmp_path: Path) -> None:
    settings = _settings(netft_port=None, camera_port=0, camera_calibration=tmp_path)
    with pytest.raises(ConfigError, match=rf"^--camera-calibration: {tmp_path}: "):
        with EmulatedRig(settings):
            pass


def test_it_must_be_opened_first() -> None:
    rig = EmulatedRig(_settings())
    with pytest.raises(NotConnectedError):
        rig.ready_line()
    with pytest.raises(NotConnectedError):
        rig.summary()
