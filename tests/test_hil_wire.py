"""Both arms over the wire (docs/hil.md, protocols/hil_wire.toml): each behind its own
emulated controller over RTDE on one shared world, in lockstep. The run equals the
in-process two-arm run bit for bit on every numeric topic; a fault or a killed carrier
emulator ends both robots safely, the cause in the recording, one line on the terminal."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from typer.testing import CliRunner

from drivers.carrier.plant import JointReading, WirePlant
from ffexp.cli import app
from ffexp.hil.protocol import DeviceLink, LinkSettings, load_hil_protocol
from ffexp.hil.record import record_impact, run_protocol

ROOT = Path(__file__).resolve().parents[1]
WIRE = ROOT / "protocols/hil_wire.toml"
NUMERIC = ("/carrier/state", "/hil/ideal", "/hil/contact")
runner = CliRunner()


def messages(path: Path) -> dict[str, list[tuple[int, bytes]]]:
    out: dict[str, list[tuple[int, bytes]]] = {}
    with path.open("rb") as fh:
        for _, channel, msg in make_reader(fh).iter_messages(log_time_order=False):
            out.setdefault(channel.topic, []).append((msg.log_time, bytes(msg.data)))
    return out


def on(host: str) -> LinkSettings:
    """The protocol's link with both emulators on ``host`` (each test its own address)."""
    return LinkSettings(chaser=DeviceLink(emulator="ur5e", host=host),
                        carrier=DeviceLink(emulator="ur5e", host=host))


def test_over_the_wire_equals_in_process_bit_for_bit(tmp_path: Path) -> None:
    proto = load_hil_protocol(WIRE)
    wire = record_impact(run_protocol(proto.model_copy(update={"link": on("127.0.0.41")})),
                         tmp_path / "wire.mcap")
    local = record_impact(run_protocol(proto.model_copy(update={"link": None})),
                          tmp_path / "local.mcap")
    a, b = messages(wire), messages(local)
    for topic in NUMERIC:
        assert len(a[topic]) > 50
        assert a[topic] == b[topic], topic
    assert "/carrier/event" not in a and "/carrier/event" not in b


def test_seven_joints_over_the_wire_equal_in_process(tmp_path: Path) -> None:
    """The chaser the zero-g scene's LWR4+ (seven joints, its targets in the registers)."""
    proto = load_hil_protocol(WIRE)
    proto = proto.model_copy(update={"scene_set": ("carrier.model='arm'",),
                                     "link": on("127.0.0.42")})
    wire = messages(record_impact(run_protocol(proto), tmp_path / "wire.mcap"))
    local = messages(record_impact(run_protocol(proto.model_copy(update={"link": None})),
                                   tmp_path / "local.mcap"))
    for topic in NUMERIC:
        assert wire[topic] == local[topic], topic


def _cycles(path: Path) -> np.ndarray:
    rows = [np.frombuffer(d[4:], dtype="<f8") for _, d in messages(path)["/carrier/state"]]
    return np.array(rows)


def _events(path: Path) -> list[dict[str, object]]:
    return [json.loads(d) for _, d in messages(path).get("/carrier/event", [])]


@pytest.mark.parametrize(("sets", "cause"), [
    (("--set", "faults.carrier_emulator_killed_at_s=0.04"), "carrier link lost"),
    (("--set", "faults.link_lost_at_s=0.04"), "carrier link lost"),
    (("--set", "faults.ft_stale_at_s=0.04"), "carrier F/T stale"),
    (("--scene-set", "carrier.workspace_m=[0.0005, 0.5, 0.5]"), "carrier workspace"),
])
def test_a_fault_over_the_wire_ends_both_robots_safely(
        tmp_path: Path, sets: tuple[str, str], cause: str) -> None:
    """One line, exit 3; the event names the device and why; every cycle until the end
    recorded; after the hold the carrier's flange stands still and the chaser's tool too."""
    proc = subprocess.run(
        [sys.executable, "-m", "ffexp", "hil", str(WIRE), "--out", str(tmp_path), *sets,
         "--set", "link.chaser.host='127.0.0.43'", "--set", "link.carrier.host='127.0.0.43'"],
        capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 3, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("carrier held at "), proc.stderr
    assert cause in lines[0] and "chaser stopped" in lines[0]
    path = tmp_path / "hil_wire.mcap"
    events = _events(path)
    assert [e["device"] for e in events] == ["carrier", "chaser"]
    assert cause in str(events[0]["cause"])
    held = float(events[0]["t_s"])  # type: ignore[arg-type]
    rows = _cycles(path)
    t = np.arange(len(rows)) * 0.002
    assert t[-1] >= held + 0.018  # the run went on ten cycles after the hold, all recorded
    flange = rows[:, 12:15]
    after = t > held + 0.0041  # the last targets reached
    assert np.abs(flange[after] - flange[after][0]).max() < 1e-4
    tool = [np.frombuffer(d[4:], dtype="<f8")[3] for ts, d in messages(path)["/hil/contact"]
            if ts > (held + 0.0021) * 1e9]
    assert tool and max(tool) - min(tool) < 1e-9  # the chaser stopped


def test_a_link_to_an_unknown_emulator_is_one_line_exit_2(tmp_path: Path) -> None:
    res = runner.invoke(app, ["hil", str(WIRE), "--out", str(tmp_path),
                              "--set", "link.carrier.emulator='abb'"])
    assert res.exit_code == 2
    assert res.output.strip().count("\n") == 0 and "link.carrier.emulator" in res.output
    assert not list(tmp_path.iterdir())


def test_a_link_needs_the_carrier_as_an_arm(tmp_path: Path) -> None:
    res = runner.invoke(app, ["hil", str(WIRE), "--out", str(tmp_path),
                              "--scene-set", "carrier.model='interpolator'"])
    assert res.exit_code == 2
    assert "carrier.model" in res.output and res.output.strip().count("\n") == 0
    assert not list(tmp_path.iterdir())


class _Fake:
    """A joint link that fails on its n-th read or send (a lost connection)."""

    def __init__(self, name: str, fail_read_at: int = -1, fail_send_at: int = -1) -> None:
        self.name, self.reads, self.sends, self.closed = name, 0, 0, False
        self.fail_read_at, self.fail_send_at = fail_read_at, fail_send_at

    def read(self) -> JointReading:
        from drivers.errors import LinkLostError

        self.reads += 1
        if self.reads == self.fail_read_at:
            raise LinkLostError(f"{self.name}: connection closed")
        return JointReading(0.002 * self.reads, np.full(6, float(self.reads)), np.zeros(6))

    def send(self, q: np.ndarray, qd: np.ndarray) -> None:
        from drivers.errors import LinkLostError

        self.sends += 1
        if self.sends == self.fail_send_at:
            raise LinkLostError(f"{self.name}: broken pipe")

    def close(self) -> None:
        self.closed = True


@pytest.mark.parametrize(("read_at", "send_at", "words"), [(3, -1, "connection closed"),
                                                            (-1, 2, "broken pipe")])
def test_a_carrier_link_lost_on_read_or_send_leaves_the_chaser_going(
        read_at: int, send_at: int, words: str) -> None:
    carrier, chaser = _Fake("carrier", read_at, send_at), _Fake("chaser")
    plant = WirePlant(carrier, chaser)
    first = plant.start()
    assert first.lost is None and first.carrier_q[0] == 1.0
    zero = np.zeros(6)
    cycles = [plant.step(zero, zero, zero, zero) for _ in range(4)]
    lost = [c.lost for c in cycles]
    assert lost[-1] is not None and words in lost[-1] and lost[-1].startswith("carrier link lost")
    assert carrier.closed and chaser.reads == 5 and chaser.sends == 4
    # the carrier's state stays as last read once lost
    assert cycles[-1].carrier_q[0] == cycles[-2].carrier_q[0]
