"""The experiment loop on stand-in devices: call order, phases, safe stops, tare.

Devices are ``Mock(spec=...)`` of the driver interfaces; nothing is written
to disk (the run log keeps only its events).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from unittest.mock import Mock, call

import numpy as np
import pytest
from loop_script import CYCLE_NS, cycles, pose_at

from drivers.base.interfaces import ForceTorqueSensor, RobotDriver
from drivers.base.types import (
    AppliedCommand,
    CartesianCommand,
    FtSamples,
    FtStatus,
    LinkHealth,
    RobotState,
)
from drivers.errors import DriverError, DriverTimeoutError, LinkLostError, SimulationError
from ffexp import loop
from ffexp.contracts import Phase, RunOutcome, StopReason
from ffexp.protocol import RunProtocol
from ffexp.runlog import RunLog

PROTOCOL = RunProtocol.model_validate(
    {"name": "mock", "align": {"method": "force_ri"}, "run": {"timeout_s": 30.0}}
)


class Rig:
    """A Mock robot and sensor sharing one call log, replaying a script."""

    def __init__(self, states: list[RobotState], fts: list[FtSamples],
                 fail_at: int | None = None, error: DriverError | None = None) -> None:
        self.manager = Mock()
        self.robot = Mock(spec=RobotDriver)
        self.sensor = Mock(spec=ForceTorqueSensor)
        self.manager.attach_mock(self.robot, "robot")
        self.manager.attach_mock(self.sensor, "sensor")
        self.intents: list[CartesianCommand | None] = []

        def measurements() -> Iterator[RobotState]:
            for i, s in enumerate(states):
                if fail_at is not None and i == fail_at:
                    raise error or LinkLostError("gone")
                yield s

        def send(cmd: CartesianCommand | None) -> AppliedCommand:
            self.intents.append(None if cmd is None else cmd.copy())
            return AppliedCommand(command=CartesianCommand() if cmd is None else cmd.copy())

        self.robot.measurements.side_effect = measurements
        self.robot.send.side_effect = send
        self.sensor.samples.side_effect = list(fts)

    def run(self, protocol: RunProtocol = PROTOCOL, **kw: object) -> tuple[RunOutcome, RunLog]:
        log = RunLog(None, 0, protocol.run.tf_period_s)
        return loop.run(protocol, self.robot, self.sensor, log, **kw), log  # type: ignore[arg-type]

    def order(self) -> list[str]:
        return [c[0] for c in self.manager.mock_calls]


def phases(log: RunLog) -> list[str]:
    return [m.split(": ")[0] for _t, name, m in log.events if name == "phase"][1:]


def test_call_order_one_send_per_state() -> None:
    states, fts = cycles(40)
    rig = Rig(states, fts)
    out, _log = rig.run()
    order = rig.order()
    assert order[:3] == ["robot.connect", "sensor.start", "robot.measurements"]
    body = order[3:-2]
    assert body == ["sensor.samples", "robot.send"] * 40
    assert order[-2:] == ["sensor.stop", "robot.close"]
    assert out.cycles == 40
    assert out.stop_reason is StopReason.ROBOT_STOPPED  # the script ended mid-run


@pytest.mark.parametrize(
    ("error", "reason"),
    [(LinkLostError("cable"), StopReason.LINK_LOST),
     (DriverTimeoutError("no packet"), StopReason.ROBOT_TIMEOUT),
     (SimulationError("diverged"), StopReason.DRIVER_ERROR)],
)
def test_device_errors_close_and_name_their_kind(error: DriverError, reason: StopReason) -> None:
    states, fts = cycles(120)
    rig = Rig(states, fts, fail_at=100, error=error)
    out, _log = rig.run()
    assert rig.order()[-2:] == ["sensor.stop", "robot.close"]
    assert out.phase is Phase.ABORT and out.stop_reason is reason
    assert str(error) in out.reason
    assert out.cycles == 100


def test_close_even_when_send_raises() -> None:
    states, fts = cycles(10)
    rig = Rig(states, fts)
    rig.robot.send.side_effect = RuntimeError("bug in a driver")
    with pytest.raises(RuntimeError):
        rig.run()
    assert rig.manager.mock_calls[-2:] == [call.sensor.stop(), call.robot.close()]


def test_tare_then_approach_then_align_and_a_break() -> None:
    # contact (f_z 2 N) from cycle 100 to 199, then free again
    states, fts = cycles(320, contact_n=lambda i: 2.0 if 100 <= i < 200 else 0.0)
    rig = Rig(states, fts)
    out, log = rig.run()
    assert phases(log)[:3] == ["CONNECT -> APPROACH", "APPROACH -> ALIGN", "ALIGN -> APPROACH"]
    assert out.contacts == 1 and out.breaks == 1
    # CONNECT keeps the robot's own set-point; then Cartesian commands
    first_cmd = next(i for i, c in enumerate(rig.intents) if c is not None)
    assert all(c is None for c in rig.intents[:first_cmd])
    assert first_cmd == 49  # 250 samples of 1 kHz cover 0.25 s: that cycle commands
    tare = next(m for _t, n, m in log.events if n == "tare")
    assert "tared from 250 samples" in tare


def test_tare_needs_sensor_time_not_a_sample_count() -> None:
    # a slow sensor (one sample per 5 ms cycle, like fri-estimate) tares after 0.25 s too
    def one_sample(i: int, s: RobotState, ft: FtSamples) -> None:
        ft.time_ns, ft.seq = ft.time_ns[-1:], ft.seq[-1:]
        ft.wrench, ft.status = ft.wrench[-1:], ft.status[-1:]

    states, fts = cycles(80, edit=one_sample)
    rig = Rig(states, fts)
    _out, log = rig.run()
    t_tare = next(t for t, n, _m in log.events if n == "tare")
    assert t_tare == pytest.approx(0.245, abs=1e-9)  # 50 samples cover 250 ms


def test_tare_removes_the_bias() -> None:
    states, fts = cycles(80)
    log = RunLog(None, 0, 0.02)
    cyc = None
    for s, ft in zip(states, fts, strict=True):
        cyc = cyc or loop.Cycle(PROTOCOL, s, log)
        cyc.step(s, ft)
    assert cyc is not None
    np.testing.assert_allclose(cyc.estimator.out.bias, [0.3, -0.2, 0.5, 0.01, 0.0, 0.0],
                               atol=0.01)
    assert abs(cyc.estimator.out.f_z) < 0.05


def stop_time(out: RunOutcome) -> float:
    """Run time of the phase change to ABORT (the run goes on for the safe-stop hold)."""
    return next(t for t, name, m in out.events if name == "phase" and "-> ABORT" in m)


def _abort(states: list[RobotState], fts: list[FtSamples], **kw: object) -> tuple[RunOutcome, Rig]:
    rig = Rig(states, fts)
    out, _log = rig.run(**kw)
    return out, rig


def _assert_safe_stop(rig: Rig, pose: np.ndarray) -> None:
    last = rig.intents[-1]
    assert last is not None
    np.testing.assert_array_equal(last.wrench_n_nm, 0.0)
    np.testing.assert_array_equal(last.stiffness_npm_nmprad, PROTOCOL.krc.hold_stiffness)
    np.testing.assert_allclose(last.pose_m, pose)


def test_force_spike_aborts_with_a_safe_stop_held() -> None:
    states, fts = cycles(200, contact_n=lambda i: 80.0 if i == 120 else 0.0)
    out, rig = _abort(states, fts)
    assert out.stop_reason is StopReason.FORCE_LIMIT and out.phase is Phase.ABORT
    _assert_safe_stop(rig, pose_at(0.0))
    # the stop is held for run.stop_hold_s (0.1 s = 20 cycles), then the loop ends
    assert out.cycles == 121 + 20


def test_torque_limit() -> None:
    def twist(i: int, s: RobotState, ft: FtSamples) -> None:
        if i == 120:
            ft.wrench[:, 3] += 4.0

    out, _rig = _abort(*cycles(200, edit=twist))
    assert out.stop_reason is StopReason.TORQUE_LIMIT


def test_saturation_bit() -> None:
    def saturate(i: int, s: RobotState, ft: FtSamples) -> None:
        if i == 90:
            ft.status[2] = FtStatus.SATURATION

    out, _rig = _abort(*cycles(200, edit=saturate))
    assert out.stop_reason is StopReason.FT_SATURATED


def test_stale_sensor() -> None:
    out, _rig = _abort(*cycles(200, ft_until=100))
    assert out.stop_reason is StopReason.FT_STALE


def test_robot_leaves_command_mode() -> None:
    def mon(i: int, s: RobotState, ft: FtSamples) -> None:
        if i >= 100:
            s.link = LinkHealth(commanding=False, healthy=True, cycle=i)

    out, _rig = _abort(*cycles(200, edit=mon))
    assert out.stop_reason is StopReason.LINK_BAD
    assert stop_time(out) == pytest.approx((100 + 9) * CYCLE_NS / 1e9)  # the 10th bad cycle


def test_speed_limit() -> None:
    def fly(i: int, s: RobotState, ft: FtSamples) -> None:
        s.tcp_pose_m = pose_at(0.0, y=0.0 if i < 100 else (i - 100) * 0.002)  # 0.4 m/s

    out, _rig = _abort(*cycles(200, edit=fly))
    assert out.stop_reason is StopReason.SPEED_LIMIT


def test_workspace_limit() -> None:
    def drift(i: int, s: RobotState, ft: FtSamples) -> None:
        s.tcp_pose_m = pose_at(0.0, y=0.0 if i < 100 else (i - 100) * 0.0004)  # 8 cm/s

    out, _rig = _abort(*cycles(700, edit=drift))
    assert out.stop_reason is StopReason.WORKSPACE_LIMIT
    assert stop_time(out) == pytest.approx(0.5 + 0.15 / 0.08, abs=0.01)


def test_stop_request_is_a_safe_stop() -> None:
    n = [0]

    def stop() -> bool:
        n[0] += 1
        return n[0] > 120

    out, rig = _abort(*cycles(300), stop_requested=stop)
    assert out.stop_reason is StopReason.STOP_REQUESTED and out.phase is Phase.ABORT
    _assert_safe_stop(rig, pose_at(0.0))


def test_timeout_ends_done_and_holds_the_pose_reached() -> None:
    protocol = PROTOCOL.model_copy(update={"run": PROTOCOL.run.model_copy(
        update={"timeout_s": 0.75})})

    def creep(i: int, s: RobotState, ft: FtSamples) -> None:
        s.tcp_pose_m = pose_at(i * 1e-4)

    states, fts = cycles(400, edit=creep)
    rig = Rig(states, fts)
    out, _log = rig.run(protocol)
    assert out.phase is Phase.DONE and out.stop_reason is StopReason.TIMEOUT
    assert not out.aligned
    _assert_safe_stop(rig, pose_at(150 * 1e-4))  # where the tool was at t = 0.75 s


def _chunk_order_violations(path: Path) -> dict[str, int]:
    """Messages whose log time is below an earlier one's in the same chunk, per topic
    (read with the plain mcap stream reader, as an independent checker would)."""
    import io

    import zstandard
    from mcap.exceptions import EndOfFile
    from mcap.records import Channel, Chunk, Message
    from mcap.stream_reader import StreamReader

    topics: dict[int, str] = {}
    bad: dict[str, int] = {}
    with path.open("rb") as fh:
        for rec in StreamReader(fh, emit_chunks=True).records:
            if isinstance(rec, Channel):
                topics[rec.id] = rec.topic
            if not isinstance(rec, Chunk):
                continue
            data = rec.data
            if rec.compression == "zstd":
                data = zstandard.ZstdDecompressor().decompress(
                    data, max_output_size=rec.uncompressed_size)
            inner = []
            try:
                for r in StreamReader(io.BytesIO(data), skip_magic=True).records:
                    inner.append(r)
            except EndOfFile:  # a chunk's records end without a footer
                pass
            newest = -1
            for r in inner:
                if isinstance(r, Channel):
                    topics[r.id] = r.topic
                elif isinstance(r, Message):
                    if r.log_time < newest:
                        bad[topics[r.channel_id]] = bad.get(topics[r.channel_id], 0) + 1
                    newest = max(newest, r.log_time)
    return bad


@pytest.mark.parametrize("ahead_ns", [0, 3_000_000, 12_000_000])
def test_the_recording_is_in_log_time_order_within_chunks(tmp_path: Path, ahead_ns: int) -> None:
    """F/T samples stamped after the cycle's time (a sensor clock ahead of the robot's)
    are written after the cycle's topics, not before them."""
    from ffexp.recording import Recorder

    def shift(i: int, s: RobotState, ft: FtSamples) -> None:
        ft.time_ns += ahead_ns

    states, fts = cycles(200, edit=shift)
    rig = Rig(states, fts)
    path = tmp_path / "run.mcap"
    with Recorder(path) as rec:
        log = RunLog(rec, 1_700_000_000 * 10**9, PROTOCOL.run.tf_period_s)
        loop.run(PROTOCOL, rig.robot, rig.sensor, log)  # type: ignore[arg-type]
    assert _chunk_order_violations(path) == {}
    from ffexp.recording import load

    got = load(path).topic("/ft/raw")
    assert len(got) == 5 * 200  # every sample written once
    assert np.all(np.diff(got.log_time_ns) > 0)


def test_the_heap_is_frozen_during_a_run_and_after_it_as_before() -> None:
    """The run freezes the objects that exist at its start (the collector skips them)
    and unfreezes them after it, even when the driver fails; a caller's own freeze is
    left alone."""
    import gc

    states, fts = cycles(40)
    seen: list[int] = []
    rig = Rig(states, fts, fail_at=30)

    def send(cmd: CartesianCommand | None) -> AppliedCommand:
        seen.append(gc.get_freeze_count())
        return AppliedCommand(command=CartesianCommand())

    rig.robot.send.side_effect = send
    assert gc.get_freeze_count() == 0
    out, _log = rig.run()
    assert out.stop_reason is StopReason.LINK_LOST
    assert len(seen) == 30 and min(seen) > 1000  # the test's own modules and objects
    assert gc.get_freeze_count() == 0
    gc.freeze()
    try:
        frozen = gc.get_freeze_count()
        with loop.frozen_heap():
            assert gc.get_freeze_count() == frozen
        assert gc.get_freeze_count() == frozen
    finally:
        gc.unfreeze()
