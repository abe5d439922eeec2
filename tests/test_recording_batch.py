"""A batch's recordings (ffexp.recording.batch): each run's messages, encoded for the
batch at once, are the bytes the run's own recorder makes of the same values alone;
each run's file holds what it holds when written alone; a run leaves the batch with
its file finished; a lean batch keeps only the lean topics and says so."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from ffexp.recording import Recorder, load
from ffexp.recording.batch import LEAN_TOPICS, BatchEncoder, BatchRecorder, lean_topic
from ffexp.recording.topics import CDR_TOPICS, STATE_JOINTS

START_NS = 1_700_000_000_000_000_000
RUNS = 4
FT_MESSAGE = CDR_TOPICS["/ft/raw"].spec.new_record().tobytes()


def _estimates(rng: np.random.Generator, runs: int) -> list[SimpleNamespace]:
    """Per run an estimate with its own values (NaN, -0.0 and integer extremes among
    them), as the estimator's output holds them."""
    out = []
    for i in range(runs):
        wrench = rng.normal(size=6)
        wrench[i % 6] = np.nan if i == 1 else -0.0
        out.append(SimpleNamespace(wrench=wrench, wrench_std=rng.random(6),
                                   bias=rng.normal(size=6) * 1e-3, twist_tcf=rng.normal(size=6),
                                   f_z=float(-wrench[2]), n_samples=int(rng.integers(0, 2**32)),
                                   in_contact=i % 2))
    return out


def _states(rng: np.random.Generator, runs: int) -> list[SimpleNamespace]:
    out = []
    for i in range(runs):
        pose = np.eye(4)
        pose[:3, :3] = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        pose[:3, 3] = rng.normal(size=3)
        out.append(SimpleNamespace(
            time_ns=int(rng.integers(-2**62, 2**62)), tcp_pose=pose,
            joint_pos=rng.normal(size=STATE_JOINTS), n_joints=7 - i, commanding=i % 2, healthy=1,
            cycle=int(rng.integers(0, 2**31)), cycle_s=0.005 * (i + 1), has_twist=1,
            twist=rng.normal(size=6), has_ext_wrench=0, ext_wrench=np.zeros(6)))
    return out


@pytest.mark.parametrize("topic,make", [("/estimator/state", _estimates),
                                        ("/robot/state", _states)])
def test_batch_messages_equal_each_runs_own(tmp_path: Path, topic: str, make: object) -> None:
    rng = np.random.default_rng(7)
    sources = make(rng, RUNS)  # type: ignore[operator]
    with Recorder(tmp_path / "alone.mcap") as rec:
        alone = [rec.encode_fields(topic, s) for s in sources]
    enc = BatchEncoder(topic, RUNS)
    enc.fill_from(sources)
    assert enc.messages() == alone
    # the same from arrays with the run axis first, field by field
    by_field = BatchEncoder(topic, RUNS)
    for f in by_field.spec.fields:
        by_field.set(f.name, np.stack([np.asarray(getattr(s, f.name)) for s in sources]))
    assert by_field.messages() == alone
    assert len(alone[0]) == enc.spec.dtype.itemsize


def test_batch_encoder_refuses_what_does_not_fit() -> None:
    enc = BatchEncoder("/estimator/state", 3)
    with pytest.raises(KeyError, match="no field 'nope'"):
        enc.set("nope", [1, 2, 3])
    with pytest.raises(ValueError, match="2 sources for 3 runs"):
        enc.fill_from([SimpleNamespace(), SimpleNamespace()])
    with pytest.raises(ValueError, match="at least one run"):
        BatchEncoder("/estimator/state", 0)


def _cycle_messages(rng: np.random.Generator, runs: int) -> tuple[
        list[SimpleNamespace], list[SimpleNamespace], list[bytes | None]]:
    ests, states = _estimates(rng, runs), _states(rng, runs)
    tf = [f'{{"x":{i}}}'.encode() if i % 2 else None for i in range(runs)]
    return ests, states, tf


def _write_alone(path: Path, run: int, cycles: list[tuple[int, SimpleNamespace,
                                                           SimpleNamespace, bytes | None]],
                 lean: bool) -> None:
    with Recorder(path) as rec:
        rec.metadata("recording", {"lean": "true" if lean else "false",
                                   "topics": ",".join(sorted(LEAN_TOPICS) if lean else ["*"])})
        for t, st, est, tf in cycles:
            msgs = [("/robot/state", rec.encode_fields("/robot/state", st))]
            if not lean:
                msgs.append(("/ft/raw", FT_MESSAGE))
            msgs.append(("/estimator/state", rec.encode_fields("/estimator/state", est)))
            if tf is not None and not lean:
                msgs.append(("/tf", tf))
            rec.write_batch(t, msgs)
        rec.write_json("/events", cycles[-1][0], {"name": f"end {run}"})


@pytest.mark.parametrize("lean", [False, True])
def test_each_runs_file_equals_the_run_written_alone(tmp_path: Path, lean: bool) -> None:
    rng = np.random.default_rng(11)
    ends = [40, 17, 40, 29]  # runs 1 and 3 leave the batch early (aligned, aborted)
    paths = [tmp_path / f"batch{i}.mcap" for i in range(RUNS)]
    batch = BatchRecorder([Recorder(p) for p in paths], lean=lean)
    history: list[list[tuple[int, SimpleNamespace, SimpleNamespace, bytes | None]]] = [
        [] for _ in range(RUNS)]
    ft = [FT_MESSAGE] * RUNS
    for k in range(40):
        ests, states, tf = _cycle_messages(rng, RUNS)
        log_ns = [START_NS + 5_000_000 * k + 1000 * i for i in range(RUNS)]
        est_enc, state_enc = batch.encoder("/estimator/state"), batch.encoder("/robot/state")
        est_enc.fill_from(ests)
        state_enc.fill_from(states)
        batch.cycle(log_ns, [("/robot/state", state_enc), ("/ft/raw", ft),
                             ("/estimator/state", est_enc), ("/tf", tf)])
        for i in batch.active:
            history[i].append((log_ns[i], states[i], ests[i], tf[i]))
            if k + 1 == ends[i]:
                batch.write_json(i, "/events", log_ns[i], {"name": f"end {i}"})
                batch.finish_run(i)
        if k == 20:
            assert batch.active == [0, 2, 3]
    batch.finish()
    assert batch.active == []
    for i, path in enumerate(paths):
        alone = tmp_path / f"alone{i}.mcap"
        _write_alone(alone, i, history[i], lean)
        got, want = load(path), load(alone)
        assert got.complete and not got.warnings
        assert got.metadata["recording"]["lean"] == ("true" if lean else "false")
        assert sorted(got.topics) == sorted(want.topics)
        assert ("/ft/raw" in got.topics) is not lean
        for topic in ("/robot/state", "/estimator/state"):
            a, b = got.topic(topic), want.topic(topic)
            assert len(a) == ends[i]
            assert a.log_time_ns.tolist() == b.log_time_ns.tolist()
            for name in a.fields:  # bit for bit (NaN where NaN)
                assert a[name].tobytes() == b[name].tobytes(), (i, topic, name)
        assert got.json["/events"].messages == [{"name": f"end {i}"}]


def test_lean_topics_are_what_analysis_reads() -> None:
    assert lean_topic("/estimator/state") and lean_topic("/control/terms")
    assert not lean_topic("/ft/raw") and not lean_topic("/tf")
    assert not lean_topic("/robot/measurement")
    # the truth's topics, under the prefix its back-end gives them
    assert lean_topic("/sim/body/target", "/sim") and lean_topic("/sim/truth", "/sim/")
    assert not lean_topic("/sim/body/target") and not lean_topic("/simulated", "/sim")
