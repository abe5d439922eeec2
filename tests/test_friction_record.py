"""``record_result`` writes through the run recorder: registered topics, schemas
from :mod:`ffexp.recording.topics`, readable by :func:`ffexp.recording.load`."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from ffexp.friction import Scale, SynthConfig, estimate_video, write_video
from ffexp.friction.record import RESULT_TOPIC, TRACK_TOPIC, record_result
from ffexp.recording import load
from ffexp.recording.topics import JSON_TOPICS


def test_friction_topics_are_registered_with_their_schemas() -> None:
    track, result = JSON_TOPICS[TRACK_TOPIC], JSON_TOPICS[RESULT_TOPIC]
    assert track.schema_name == "ffexp.friction.TrackSample"
    assert result.schema_name == "ffexp.friction.Result"
    assert {"frame", "t_s", "valid", "s_m"} <= set(track.schema["properties"])
    assert {"mu", "mu_std", "decel_mps2"} <= set(result.schema["required"])


def test_record_result_round_trip(tmp_path: Path) -> None:
    video = tmp_path / "v.avi"
    cfg = SynthConfig(
        mu=0.03, v0_mps=0.2, duration_s=0.8, width_px=320, height_px=180,
        px_per_m=282.5, rest_s=0.2,
    )  # fmt: skip
    write_video(cfg, video, np.random.default_rng(5))
    result = estimate_video(video, Scale(px_per_m=282.5))
    out = tmp_path / "sub" / "f.mcap"
    record_result(result, out)

    rec = load(out)
    assert set(rec.json) == {TRACK_TOPIC, RESULT_TOPIC}
    track = rec.json[TRACK_TOPIC]
    n = len(result.track.t_s)
    assert len(track) == n
    assert [m["frame"] for m in track.messages] == list(range(n))
    assert track.log_time_ns.tolist() == [round(float(t) * 1e9) for t in result.track.t_s]
    assert sum(m["in_window"] for m in track.messages) == len(result.window_idx)
    (res,) = rec.json[RESULT_TOPIC].messages
    assert res["mu"] == pytest.approx(result.estimate.mu)
    assert rec.json[RESULT_TOPIC].log_time_ns.tolist() == [round(result.estimate.fit.t_end_s * 1e9)]
    assert rec.metadata["friction"] == {"video": str(video)}
    # invalid frames carry null, never NaN (strict JSON)
    for m in track.messages:
        for key in ("u_px", "v_px", "x_m", "y_m", "s_m"):
            assert m[key] is None or math.isfinite(m[key])

    # the schema in the file is the registry's
    with out.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    by_name = {s.name: s for s in summary.schemas.values()}
    stored = json.loads(by_name["ffexp.friction.TrackSample"].data)
    assert stored == JSON_TOPICS[TRACK_TOPIC].schema
