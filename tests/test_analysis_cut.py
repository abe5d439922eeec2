"""Analysis of a file cut between the two messages of one cycle (a killed, recovered run)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ffexp.analysis import metrics, series
from ffexp.experiment import RigChoice, run_file
from ffexp.recording import load
from ffexp.recording.reader import TopicData

ROOT = Path(__file__).resolve().parents[1]


def _cut(data: TopicData, n: int) -> TopicData:
    return TopicData(data.log_time_ns[:n], {k: v[:n] for k, v in data.fields.items()})


def test_a_cycle_with_only_its_estimate_is_left_out(tmp_path: Path) -> None:
    result = run_file(ROOT / "protocols/method1_case1.toml", ["run.timeout_s=0.6"],
                      rig=RigChoice(path=ROOT / "rigs/mock.toml"), out_dir=tmp_path)
    rec = load(result.path)
    whole = series(rec)
    n = len(rec.topic("/control/terms"))
    rec.topics["/control/terms"] = _cut(rec.topic("/control/terms"), n - 1)
    cut = series(rec)
    assert len(cut.t_s) == n - 1 == len(whole.t_s) - 1
    np.testing.assert_array_equal(cut.wrench, whole.wrench[: n - 1])
    np.testing.assert_array_equal(cut.phase, whole.phase[: n - 1])
    assert metrics(rec).duration_s == cut.t_s[-1]
