"""Every abort condition of the SafetyMonitor, each on its own (pure: no device, no file)."""

from __future__ import annotations

import numpy as np
import pytest
from loop_script import pose_at

from drivers.base.types import LinkHealth, RobotState
from ffexp.contracts import Phase, StopReason
from ffexp.estimation import Estimate
from ffexp.safety import Limits, SafetyMonitor

LIM = Limits(max_force_n=60.0, max_torque_nm=3.0, max_speed_mps=0.25,
             workspace_m=(0.05, 0.15, 0.35), stale_ft_s=0.05, link_lost_cycles=3)


def calm() -> tuple[RobotState, Estimate]:
    est = Estimate(n_samples=5, peak_force_n=1.0, peak_torque_nm=0.1, last_sample_ns=0)
    return RobotState(tcp_pose_m=pose_at(0.0)), est


def monitor() -> SafetyMonitor:
    m = SafetyMonitor(LIM)
    m.set_origin(pose_at(0.0))
    return m


def test_calm_cycle_passes() -> None:
    s, e = calm()
    assert monitor().check(0, Phase.ALIGN, s, e) is None


@pytest.mark.parametrize(
    ("field", "value", "reason"),
    [
        ("saturated", True, StopReason.FT_SATURATED),
        ("peak_force_n", 60.5, StopReason.FORCE_LIMIT),
        ("peak_torque_nm", 3.01, StopReason.TORQUE_LIMIT),
    ],
)
def test_sensor_limits(field: str, value: object, reason: StopReason) -> None:
    s, e = calm()
    setattr(e, field, value)
    stop = monitor().check(0, Phase.CONNECT, s, e)
    assert stop is not None and stop.reason is reason
    # exactly at the limit is still fine
    if field == "peak_force_n":
        e.peak_force_n = 60.0
        assert monitor().check(0, Phase.CONNECT, s, e) is None


def test_stale_sensor_data() -> None:
    s, e = calm()
    e.n_samples = 0
    e.last_sample_ns = 0
    assert monitor().check(50_000_000, Phase.APPROACH, s, e) is None  # exactly 50 ms
    stop = monitor().check(51_000_000, Phase.APPROACH, s, e)
    assert stop is not None and stop.reason is StopReason.FT_STALE
    assert "51 ms" in stop.message


def test_unhealthy_link_counts_consecutive_cycles() -> None:
    s, e = calm()
    m = monitor()
    s.link = LinkHealth(healthy=False)
    assert m.check(0, Phase.CONNECT, s, e) is None
    assert m.check(0, Phase.CONNECT, s, e) is None
    s.link = LinkHealth(healthy=True)  # one good cycle resets the count
    assert m.check(0, Phase.CONNECT, s, e) is None
    s.link = LinkHealth(healthy=False)
    assert m.check(0, Phase.CONNECT, s, e) is None
    assert m.check(0, Phase.CONNECT, s, e) is None
    stop = m.check(0, Phase.CONNECT, s, e)
    assert stop is not None and stop.reason is StopReason.LINK_BAD


def test_not_commanding_counts_only_after_connect() -> None:
    s, e = calm()
    s.link = LinkHealth(commanding=False)
    m = monitor()
    for _ in range(10):
        assert m.check(0, Phase.CONNECT, s, e) is None  # MON while taring is normal
    for _ in range(2):
        assert m.check(0, Phase.APPROACH, s, e) is None
    stop = m.check(0, Phase.APPROACH, s, e)
    assert stop is not None and stop.reason is StopReason.LINK_BAD


def test_speed_limit_only_while_moving_phases() -> None:
    s, e = calm()
    e.twist_tcf = np.array([0.0, 0.2, 0.2, 0.0, 0.0, 0.0])  # 0.283 m/s
    assert monitor().check(0, Phase.CONNECT, s, e) is None
    assert monitor().check(0, Phase.DONE, s, e) is None
    stop = monitor().check(0, Phase.APPROACH, s, e)
    assert stop is not None and stop.reason is StopReason.SPEED_LIMIT
    e.twist_tcf = np.array([0.0, 0.0, 0.0, 5.0, 0.0, 0.0])  # turning only: not a speed
    assert monitor().check(0, Phase.ALIGN, s, e) is None


@pytest.mark.parametrize(("dz", "dy", "out"), [(0.34, 0.0, False), (0.36, 0.0, True),
                                                (0.0, 0.16, True), (-0.36, 0.0, True)])
def test_workspace_box_in_the_start_tcf(dz: float, dy: float, out: bool) -> None:
    s, e = calm()
    s.tcp_pose_m = pose_at(dz, y=dy)  # TCF Z is base +x, TCF Y is base +y
    stop = monitor().check(0, Phase.ALIGN, s, e)
    assert (stop is not None and stop.reason is StopReason.WORKSPACE_LIMIT) == out


def test_first_condition_wins() -> None:
    s, e = calm()
    e.saturated = True
    e.peak_force_n = 100.0
    s.link = LinkHealth(healthy=False)
    stop = monitor().check(0, Phase.ALIGN, s, e)
    assert stop is not None and stop.reason is StopReason.FT_SATURATED


def test_stop_reasons_map_to_phases() -> None:
    assert StopReason.ALIGNED.phase is Phase.DONE
    assert StopReason.TIMEOUT.phase is Phase.DONE
    assert all(r.phase is Phase.ABORT for r in StopReason
               if r not in (StopReason.ALIGNED, StopReason.TIMEOUT))
