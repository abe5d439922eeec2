"""The runner's phases and safety paths on scripted (mock) devices."""

from __future__ import annotations

import copy
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from drivers.base.types import (
    CmdFlags,
    Command,
    FriQuality,
    FriState,
    FtSamples,
    Measurement,
)
from drivers.mock import MockFtSensor, MockRobot
from ffexp.protocol import RunProtocol
from ffexp.recording import Recorder, load
from ffexp.runner import Phase, Runner

CYCLE_NS = 5_000_000
ROOT = Path(__file__).resolve().parents[1]


class CopyingMockRobot(MockRobot):
    """The runner reuses its Command object; keep a copy of each one sent."""

    def send(self, command: Command) -> None:
        super().send(copy.deepcopy(command))


def pose_at(z: float) -> np.ndarray:
    pose = np.eye(4)
    pose[:3, :3] = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])  # TCF Z = +x
    pose[:3, 3] = [0.6 + z, 0.0, 0.5]
    return pose


def script(
    n: int,
    contact_n: Callable[[int], float] = lambda i: 0.0,
    extra: Callable[[int, Measurement, FtSamples], None] | None = None,
    ft_until: int | None = None,
) -> tuple[list[Measurement], list[FtSamples]]:
    """``n`` cycles of a still tool; ``contact_n(i)`` is f_z in cycle i (read as w_z = -f_z)."""
    rng = np.random.default_rng(0)
    bias = np.array([0.3, -0.2, 0.5, 0.01, 0.0, 0.0])
    ms, fts = [], []
    for i in range(n):
        m = Measurement(seq=i, time_ns=1_000_000_000 + i * CYCLE_NS)
        m.msr_cart_pos = pose_at(0.0)
        m.cmd_cart_pos = m.msr_cart_pos.copy()
        w = np.tile(bias, (5, 1)) + rng.normal(scale=0.01, size=(5, 6))
        w[:, 2] -= contact_n(i)
        ft = FtSamples(
            time_ns=m.time_ns - CYCLE_NS + np.arange(1, 6, dtype=np.int64) * 1_000_000,
            seq=np.arange(5 * i, 5 * i + 5, dtype=np.int64),
            wrench=w,
            status=np.zeros(5, dtype=np.uint32),
        )
        if extra is not None:
            extra(i, m, ft)
        ms.append(m)
        fts.append(ft if ft_until is None or i < ft_until else FtSamples())
    return ms, fts


def run(
    tmp_path: Path,
    ms: list[Measurement],
    fts: list[FtSamples],
    protocol: RunProtocol | None = None,
    stop_at: int | None = None,
    **robot_kw: object,
) -> tuple[Runner, CopyingMockRobot, Path]:
    protocol = protocol or RunProtocol(name="mock", method="force_ri")
    robot = CopyingMockRobot(ms, **robot_kw)  # type: ignore[arg-type]
    sensor = MockFtSensor(fts)
    path = tmp_path / "run.mcap"
    calls = [0]

    def stop() -> bool:
        calls[0] += 1
        return stop_at is not None and calls[0] >= stop_at

    with Recorder(path) as rec:
        runner = Runner(
            protocol, robot, sensor, rec, start_utc_ns=1_700_000_000 * 10**9, stop_requested=stop
        )
        runner.outcome = runner.run()  # type: ignore[attr-defined]
    return runner, robot, path


def assert_safe_stop(robot: CopyingMockRobot, runner: Runner) -> None:
    last = robot.sent[-1]
    assert last is not None
    np.testing.assert_array_equal(last.add_tcp_ft, 0.0)
    np.testing.assert_allclose(last.cart_pos, pose_at(0.0))
    np.testing.assert_allclose(last.cart_stiffness, runner.p.krc.hold_stiffness)
    assert last.flags & CmdFlags.TCPFT and last.flags & CmdFlags.CARTSTIFF


def events(path: Path) -> list[dict[str, object]]:
    return load(path).json["/events"].messages


def test_contact_switches_to_align_and_loss_counts_a_break(tmp_path: Path) -> None:
    def f(i: int) -> float:
        return 1.0 if 200 <= i < 400 else 0.0

    ms, fts = script(600, f)
    runner, robot, path = run(tmp_path, ms, fts, RunProtocol(name="m", method="force_ri"))
    assert runner.contacts == 1 and runner.breaks == 1
    rec = load(path)
    phases = [m["phase"] for m in rec.json["/runner/phase"].messages]
    assert phases[:4] == ["CONNECT", "APPROACH", "ALIGN", "APPROACH"]
    ctl = rec.topic("/control/terms")
    cycle = np.arange(len(ctl))
    align = (ctl["phase"] == Phase.ALIGN) & (cycle < 400)
    assert align.sum() > 150
    # in ALIGN the command is eq. (9): here f_z = 1 > f_ref = 0.8, so F*_z < 0 (back off),
    # plus eq. (2)'s feedforward of the measured contact force (1 N)
    pi = ctl["p"][align][5:, 2] + ctl["i"][align][5:, 2]
    assert np.all(pi < 0.0)
    np.testing.assert_allclose(ctl["ff"][align][5:, 2], 1.0, atol=0.05)
    np.testing.assert_allclose(ctl["total"][align][5:, 2], pi + ctl["ff"][align][5:, 2])
    # after the force vanishes the loop pushes again until the break is confirmed
    assert np.all(ctl["total"][(ctl["phase"] == Phase.ALIGN) & (cycle > 402), 2] > 0.0)
    # in APPROACH the command is the impedance law K_e (x_sp - x): the tool stands still
    # and the set-point runs ahead at 0.02 m/s, so F_z = 500 N/m * 0.02 m/s * t
    appr = np.flatnonzero(ctl["phase"] == Phase.APPROACH)
    first = appr[appr < 200]
    elapsed = (first - first[0]) * CYCLE_NS / 1e9
    np.testing.assert_allclose(ctl["total"][first, 2], 500.0 * 0.02 * elapsed, atol=1e-9)
    # no runaway: the mock never moves, the run ends by timeout or script end
    assert robot.sent[-1] is not None


def test_force_spike_aborts_with_safe_stop(tmp_path: Path) -> None:
    def spike(i: int, m: Measurement, ft: FtSamples) -> None:
        m.msr_cart_pos = pose_at(1e-4 * i)  # the tool creeps forward
        if i == 150:
            ft.wrench[2, :3] = [80.0, 0.0, 0.0]  # above the 60 N default limit

    ms, fts = script(300, extra=spike)
    runner, robot, path = run(tmp_path, ms, fts)
    assert runner.phase == Phase.ABORT and "force limit" in runner.outcome_reason
    last = robot.sent[-1]
    assert last is not None
    np.testing.assert_array_equal(last.add_tcp_ft, 0.0)
    # the safe stop holds the pose where the tool was when it aborted, not the start
    np.testing.assert_allclose(last.cart_pos, pose_at(1e-4 * 150))
    np.testing.assert_allclose(last.cart_stiffness, runner.p.krc.hold_stiffness)
    assert any("force limit" in str(e["message"]) for e in events(path))
    # the stop hold ends the run shortly after the abort
    assert len(robot.sent) < 150 + 40


def test_stale_sensor_aborts(tmp_path: Path) -> None:
    ms, fts = script(300, ft_until=120)
    runner, robot, path = run(tmp_path, ms, fts)
    assert runner.phase == Phase.ABORT and "stale F/T" in runner.outcome_reason
    assert_safe_stop(robot, runner)
    assert any("stale" in str(e["message"]) for e in events(path))


def test_saturation_bit_aborts(tmp_path: Path) -> None:
    def sat(i: int, m: Measurement, ft: FtSamples) -> None:
        if i == 100:
            ft.status[3] = 0x00020000

    ms, fts = script(300, extra=sat)
    runner, robot, _ = run(tmp_path, ms, fts)
    assert runner.phase == Phase.ABORT and "saturated" in runner.outcome_reason
    assert_safe_stop(robot, runner)


def test_bad_link_quality_aborts(tmp_path: Path) -> None:
    def drop(i: int, m: Measurement, ft: FtSamples) -> None:
        if i >= 150:
            m.state = FriState.MON
            m.quality = FriQuality.UNACCEPTABLE

    ms, fts = script(300, extra=drop)
    runner, robot, _path = run(tmp_path, ms, fts)
    assert runner.phase == Phase.ABORT and "link lost" in runner.outcome_reason
    assert_safe_stop(robot, runner)


@pytest.mark.parametrize("kind", ["link_lost", "timeout"])
def test_driver_failure_aborts_and_keeps_the_recording(tmp_path: Path, kind: str) -> None:
    ms, fts = script(300)
    runner, _robot, path = run(tmp_path, ms, fts, fail_after=200, fail_with=kind)
    assert runner.phase == Phase.ABORT and "link lost" in runner.outcome_reason
    rec = load(path)
    assert rec.complete
    assert len(rec.topic("/robot/measurement")) == 200
    assert any(e["name"] == "fault" for e in rec.json["/events"].messages)


def test_stop_request_is_a_safe_stop(tmp_path: Path) -> None:
    ms, fts = script(300)
    runner, robot, _path = run(tmp_path, ms, fts, stop_at=120)
    assert runner.phase == Phase.ABORT and "stop requested" in runner.outcome_reason
    assert_safe_stop(robot, runner)


def test_tare_removes_the_bias(tmp_path: Path) -> None:
    ms, fts = script(200)
    _runner, _, path = run(tmp_path, ms, fts)
    est = load(path).topic("/estimator/state")
    after = est["n_samples"] > 0
    np.testing.assert_allclose(est["bias"][-1], [0.3, -0.2, 0.5, 0.01, 0.0, 0.0], atol=0.005)
    assert np.all(np.abs(est["wrench"][after][-50:, :3]) < 0.05)


def test_timeout_holds_the_pose_reached(tmp_path: Path) -> None:
    def creep(i: int, m: Measurement, ft: FtSamples) -> None:
        m.msr_cart_pos = pose_at(1e-4 * i)

    ms, fts = script(400, extra=creep)
    protocol = RunProtocol.model_validate(
        {"name": "t", "method": "force_ri", "run": {"timeout_s": 1.0}}
    )
    runner, robot, _path = run(tmp_path, ms, fts, protocol)
    assert runner.phase == Phase.DONE and runner.outcome_reason == "timeout"
    last = robot.sent[-1]
    assert last is not None
    # timeout at t = 1.0 s = cycle 200: hold there, not at the start pose
    np.testing.assert_allclose(last.cart_pos, pose_at(1e-4 * 200))
    np.testing.assert_array_equal(last.add_tcp_ft, 0.0)
