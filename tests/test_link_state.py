"""The KRC's FRI link state machine (drivers.fri.link): pure, driven cycle by cycle."""

from __future__ import annotations

import pytest

from drivers.fri.link import (
    MIN_RATED,
    WINDOW,
    KrcLink,
    LinkEvent,
    LinkWindow,
    QualityThresholds,
    quality_of,
)
from drivers.fri.types import FriQuality, FriState

CYCLE = 0.005


def test_mon_until_n_answered_then_cmd_on_the_nth() -> None:
    link = KrcLink(CYCLE, start_cycles=100)
    assert (link.state, link.quality) == (FriState.MON, FriQuality.BAD)  # nothing seen yet
    for k in range(1, 100):
        assert link.cycle(True) is LinkEvent.NONE
        assert link.state == FriState.MON
        assert link.quality == FriQuality.OK  # window not full yet
        assert link.consecutive_ok == k
    assert link.cycle(True) is LinkEvent.START  # the 100th answer is the first command taken
    assert (link.state, link.quality) == (FriState.CMD, FriQuality.PERFECT)
    assert link.starts == 1
    assert link.cycle(True) is LinkEvent.NONE


def test_start_needs_perfect_quality_as_well_as_n_answers() -> None:
    # 5 answers are enough for the script, but PERFECT needs a full window of 100
    link = KrcLink(CYCLE, start_cycles=5)
    events = [link.cycle(True) for _ in range(WINDOW)]
    assert events.index(LinkEvent.START) == WINDOW - 1
    # more than a window: CMD on the Nth answer exactly
    link = KrcLink(CYCLE, start_cycles=130)
    events = [link.cycle(True) for _ in range(200)]
    assert events.index(LinkEvent.START) == 129
    assert events.count(LinkEvent.START) == 1


def test_a_miss_restarts_the_count() -> None:
    link = KrcLink(CYCLE, start_cycles=100)
    for _ in range(150):
        link.cycle(True)
        if link.state == FriState.CMD:
            break
    assert link.state == FriState.CMD
    link = KrcLink(CYCLE, start_cycles=100)
    for _ in range(50):
        link.cycle(True)
    link.cycle(False)
    assert link.consecutive_ok == 0
    # the miss is in the window for 100 packets: no PERFECT, no start before it leaves
    events = [link.cycle(True) for _ in range(100)]
    assert events.index(LinkEvent.START) == 99
    assert link.quality == FriQuality.PERFECT


def test_start_cycles_zero_is_a_link_that_is_up() -> None:
    link = KrcLink(CYCLE, start_cycles=0)
    assert (link.state, link.quality) == (FriState.CMD, FriQuality.PERFECT)
    assert link.cycle(True) is LinkEvent.NONE
    assert (link.state, link.quality) == (FriState.CMD, FriQuality.PERFECT)


def _commanding(**kw: int) -> KrcLink:
    link = KrcLink(CYCLE, start_cycles=WINDOW, **kw)
    while link.state != FriState.CMD:
        link.cycle(True)
    return link


def test_fallback_after_max_consecutive_misses() -> None:
    link = _commanding(max_consecutive_misses=5)
    for _ in range(4):
        assert link.cycle(False) is LinkEvent.NONE
        assert link.state == FriState.CMD
    assert link.quality == FriQuality.OK  # 4 % missed
    assert link.cycle(False) is LinkEvent.FALLBACK
    assert link.state == FriState.MON
    assert (link.fallbacks, link.missed) == (1, 5)


def test_fallback_on_unacceptable_quality() -> None:
    # scattered misses (never two in a row) until more than 25 % of the window is missed
    link = _commanding(max_consecutive_misses=5)
    events = []
    for k in range(200):
        events.append(link.cycle(k % 3 != 0))
        if link.state == FriState.MON:
            break
    assert events[-1] is LinkEvent.FALLBACK
    assert link.quality == FriQuality.UNACCEPTABLE
    assert link.rates()[3] > 0.25
    assert link.consecutive_miss <= 1


def test_refuse_leaves_command_mode() -> None:
    link = _commanding()
    link.refuse()
    assert link.state == FriState.MON and link.consecutive_ok == 0 and link.fallbacks == 1
    link.refuse()  # in MON: only the count restarts
    assert link.fallbacks == 1


def test_every_cycle_answered_gives_the_in_process_sims_timing() -> None:
    """The lockstep robot's report per cycle: MON until the 100th answer, then CMD/PERFECT."""
    link = KrcLink(CYCLE, start_cycles=100)
    reported = [(link.state, link.quality)]
    for _ in range(150):
        link.cycle(True)
        reported.append((link.state, link.quality))
    assert reported[0] == (FriState.MON, FriQuality.BAD)
    assert all(r == (FriState.MON, FriQuality.OK) for r in reported[1:100])
    assert all(r == (FriState.CMD, FriQuality.PERFECT) for r in reported[100:])


def test_quality_thresholds() -> None:
    th = QualityThresholds()
    w = LinkWindow()
    assert quality_of(w, CYCLE, th, timing=True) is FriQuality.BAD  # nothing seen yet
    for _ in range(50):
        w.add(True, 0.0005)
    assert quality_of(w, CYCLE, th, timing=True) is FriQuality.OK  # window not full
    for _ in range(50):
        w.add(True, 0.0005)
    assert quality_of(w, CYCLE, th, timing=True) is FriQuality.PERFECT
    w.add(False, 0.0)
    assert quality_of(w, CYCLE, th, timing=True) is FriQuality.OK  # 1 % missed
    for _ in range(5):
        w.add(False, 0.0)
    assert quality_of(w, CYCLE, th, timing=True) is FriQuality.BAD  # 6 % > 5 %
    for _ in range(20):
        w.add(False, 0.0)
    assert quality_of(w, CYCLE, th, timing=True) is FriQuality.UNACCEPTABLE  # 26 % > 25 %
    slow = LinkWindow()
    for _ in range(WINDOW):
        slow.add(True, 0.004)  # 0.8 cycles latency
    assert quality_of(slow, CYCLE, th, timing=True) is FriQuality.BAD
    assert quality_of(slow, CYCLE, th, timing=False) is FriQuality.PERFECT  # lockstep


def test_few_packets_are_never_unacceptable() -> None:
    w = LinkWindow()
    for _ in range(MIN_RATED - 1):
        w.add(False, 0.0)
    assert quality_of(w, CYCLE, QualityThresholds(), timing=False) is FriQuality.BAD
    w.add(False, 0.0)
    assert quality_of(w, CYCLE, QualityThresholds(), timing=False) is FriQuality.UNACCEPTABLE


def test_window_rates() -> None:
    w = LinkWindow(size=4)
    assert w.rates() == (0.0, 0.0, 0.0, 0.0)
    for answered, lat in ((True, 0.001), (True, 0.003), (False, 0.0), (True, 0.002)):
        w.add(answered, lat)
    rate, mean, jitter, miss = w.rates()
    assert rate == 0.75 and miss == 0.25
    assert mean == pytest.approx(0.002)
    assert jitter == pytest.approx((2.0 / 3.0) ** 0.5 * 0.001)
    w.add(True, 0.001)  # overwrites the oldest
    assert w.rates()[0] == 0.75


def test_bad_arguments() -> None:
    with pytest.raises(ValueError, match="start_cycles"):
        KrcLink(CYCLE, start_cycles=-1)
    with pytest.raises(ValueError, match="max_consecutive_misses"):
        KrcLink(CYCLE, max_consecutive_misses=0)
