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


def test_peaks_are_reported_for_the_whole_run_and_for_align_apart(tmp_path: Path) -> None:
    """A re-approach impact (APPROACH) shows in the run's peak, not in ALIGN's."""
    from ffexp.contracts import Phase

    result = run_file(ROOT / "protocols/method1_case1.toml", ["run.timeout_s=0.6"],
                      rig=RigChoice(path=ROOT / "rigs/mock.toml"), out_dir=tmp_path)
    rec = load(result.path)
    ctl, est = rec.topic("/control/terms"), rec.topic("/estimator/state")
    n = len(ctl)
    phase = np.full(n, int(Phase.APPROACH))
    phase[: n // 4] = int(Phase.CONNECT)
    phase[n // 2:] = int(Phase.ALIGN)
    wrench = np.zeros((len(est), 6))
    wrench[n // 2:, 2] = -1.5           # pushing 1.5 N in ALIGN
    wrench[n // 3, 2] = -20.5           # an impact while re-approaching
    wrench[1, 2] = -99.0                # before the tare: not a contact
    rec.topics["/control/terms"] = TopicData(ctl.log_time_ns, {**ctl.fields, "phase": phase})
    rec.topics["/estimator/state"] = TopicData(est.log_time_ns, {**est.fields, "wrench": wrench})
    m = metrics(rec)
    assert m.peak_abs_fz_n == 1.5
    assert m.peak_abs_fz_run_n == 20.5
    assert m.peak_abs_wrench_run is not None and m.peak_abs_wrench_run[2] == 20.5
