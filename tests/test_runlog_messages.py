"""The run log's topics of a back-end's extras and of the ground truth, worked out once
per shape, are those the objects name every cycle, with the same messages."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from drivers.base.types import AttachedFrame, BodyTruth, Extras, GroundTruth
from ffexp.recording import Recorder
from ffexp.runlog import RunLog


def _truth(rng: np.random.Generator, bodies: list[str], sites: list[str],
           attached: dict[str, AttachedFrame]) -> GroundTruth:
    return GroundTruth(
        bodies={name: BodyTruth(rng.normal(size=(4, 4)), rng.normal(size=6),
                                float(rng.uniform(1, 20))) for name in bodies},
        sites={name: rng.normal(size=(4, 4)) for name in sites}, attached=attached,
        contact_wrench=rng.normal(size=6), in_contact=bool(rng.integers(0, 2)),
        tcp_twist=rng.normal(size=6))


def _reference(log: RunLog, truth: GroundTruth) -> tuple[list[str], list[bytes]]:
    """What the truth's own messages give, each kept topic encoded."""
    assert log.rec is not None
    topics, datas = [], []
    for topic, source in truth.messages():
        if log.keeps(topic):
            topics.append(topic)
            datas.append(log.rec.encode_fields(topic, source))
    return topics, datas


class _Reordered(GroundTruth):
    """A back-end's truth that names its messages its own way."""

    def messages(self) -> list[tuple[str, object]]:
        return list(reversed(super().messages()))


@pytest.mark.parametrize("lean", [False, True])
def test_the_truths_topics_follow_its_bodies_and_frames(tmp_path: Path, lean: bool) -> None:
    rng = np.random.default_rng(5)
    mouth = {"funnel_mouth": AttachedFrame("target", np.eye(4))}
    shapes = [(["target"], ["funnel_mouth"], mouth), (["target"], ["funnel_mouth"], mouth),
              (["target", "base"], ["funnel_mouth"], mouth),
              (["base", "target"], ["funnel_mouth"], mouth),  # the same bodies, reordered
              (["target"], ["funnel_mouth", "tcp"], mouth),  # a frame not attached
              (["target"], ["funnel_mouth"], {}), ([], [], {}),
              (["base", "target"], ["funnel_mouth"], mouth), (["target"], ["funnel_mouth"], mouth)]
    with Recorder(tmp_path / "r.mcap") as rec:
        log = RunLog(rec, 0, 0.1, lean=lean)
        enc = log._enc
        assert enc is not None
        for _ in range(3):
            for bodies, sites, attached in shapes:
                for truth in (_truth(rng, bodies, sites, attached),
                              _Reordered(**vars(_truth(rng, bodies, sites, attached)))):
                    topics: list[str] = []
                    datas: list[bytes] = []
                    enc.truth_into(truth, topics, datas)
                    assert (topics, datas) == _reference(log, truth)


class _Link(Extras):
    def __init__(self, names: tuple[str, ...]) -> None:
        self.names = names
        self.answer_rate, self.latency_s, self.jitter_s, self.miss_rate = 1.0, 0.1, 0.2, 0.3
        self.miss_counter, self.state, self.quality = 4, 2, 3

    def topics(self) -> tuple[str, ...]:
        return self.names


def test_an_extras_topics_are_asked_every_cycle(tmp_path: Path) -> None:
    with Recorder(tmp_path / "r.mcap") as rec:
        log = RunLog(rec, 0, 0.1, lean=True)
        enc = log._enc
        assert enc is not None
        for names in [("/robot/link",), ("/robot/measurement", "/robot/link"), ("/robot/link",),
                      ()]:
            topics: list[str] = []
            datas: list[bytes] = []
            enc.extras_into(_Link(names), topics, datas)
            assert topics == [t for t in names if log.keeps(t)]
            assert datas == [rec.encode_fields(t, _Link(names)) for t in topics]
