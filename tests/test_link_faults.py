"""The link-fault counters a back-end states (``Backend.link_faults``) are what
:func:`ffexp.linkcheck.check_link` counts: FRI's and the UR's alike, and a plug-in's.

ffexp names no back-end topic here: the counters come from the registry.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from drivers import registry
from drivers.base.backend import Backend, LinkCounter
from ffexp.contracts import Phase
from ffexp.linkcheck import align_mask, check_link, fault_topics
from ffexp.recording.reader import JsonData, Recording, TopicData, load

ROOT = Path(__file__).resolve().parents[1]


def _recording(topic: str, counts: dict[str, np.ndarray]) -> Recording:
    """Ten cycles 5 ms apart, ALIGN from cycle 4 to cycle 8, commanding and healthy."""
    t = np.arange(10, dtype=np.int64) * 5_000_000 + 10**18
    ones = np.ones(10, dtype=np.uint8)
    state = TopicData(t, {"commanding": ones, "healthy": ones})
    phases = JsonData(np.array([t[0], t[4], t[8]]), [
        {"phase_id": int(Phase.CONNECT)}, {"phase_id": int(Phase.ALIGN)},
        {"phase_id": int(Phase.DONE)}])
    return Recording(Path("x.mcap"), topics={"/robot/state": state, topic: TopicData(t, counts)},
                     json={"/runner/phase": phases})


def test_every_stated_counter_is_a_field_of_its_back_ends_topic() -> None:
    fields = {t.topic: {f.name for f in t.spec.fields}
              for t in registry.backend_cdr_topics()}
    counters = registry.link_faults()
    assert counters  # FRI's and the UR's at least
    for c in counters:
        assert c.field in fields.get(c.topic, set()), c
    names = [c.name for c in counters]
    assert len(names) == len(set(names))  # a verdict names each once
    assert set(fault_topics()) == {c.topic for c in counters}


def test_a_urs_skipped_packages_in_align_invalidate_the_trial() -> None:
    ur = next(c for c in registry.link_faults() if c.field == "skipped_packages")
    skipped = np.array([0, 2, 2, 2, 2, 3, 3, 5, 5, 9])  # +2 at 1; +1 at 5, +2 at 7; +4 at 9
    v = check_link(_recording(ur.topic, {ur.field: skipped}))
    assert not v.valid and v.trial_valid is False
    assert v.in_align == {ur.name: 3} and v.whole_run == {ur.name: 9}
    assert v.validity == f"invalid: 3 {ur.meaning} during ALIGN"
    # skipped outside ALIGN only: valid, and said
    v = check_link(_recording(ur.topic, {ur.field: np.array([0, 2, 2, 2, 2, 2, 2, 2, 2, 9])}))
    assert v.valid and v.whole_run == {ur.name: 9}
    assert v.text().endswith(f"whole run: 9 {ur.meaning})")


def test_a_plug_ins_counter_is_counted_without_an_ffexp_edit() -> None:
    toy = Backend("toy-link", link_faults=(
        LinkCounter("/toy/link", "drops", "frames dropped", key="toy_drops"),))
    rec = _recording("/toy/link", {"drops": np.array([0, 0, 0, 0, 0, 1, 1, 1, 1, 1])})
    assert check_link(rec).valid  # not a registered counter yet
    with registry.registered(toy):
        v = check_link(rec)
        assert v.in_align == {"toy_drops": 1}
        assert v.reasons() == ["1 frames dropped during ALIGN"]
        assert "/toy/link" in fault_topics()
    assert "/toy/link" not in fault_topics()


@pytest.mark.slow
def test_a_ur_sim_run_whose_reader_skips_packages_in_align_is_invalid(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """End to end: the in-process UR's link skips one data package per cycle from its
    second on; the recording's ``/robot/ur`` says so and the trial is invalid by exactly
    the cycles spent in ALIGN."""
    from drivers.ur.emulate.lockstep import LoopbackRtde
    from ffexp.experiment import RigChoice, run_file

    receive = LoopbackRtde.receive_latest

    def skipping(self: LoopbackRtde, timeout_s: float | None = None):  # type: ignore[no-untyped-def]
        package = receive(self, timeout_s)
        self.calls = getattr(self, "calls", 0) + 1
        if self.calls > 1:
            self.skipped += 1
        return package

    monkeypatch.setattr(LoopbackRtde, "receive_latest", skipping)
    result = run_file(ROOT / "protocols/method1_case1.toml", ["run.timeout_s=4.5"],
                      rig=RigChoice(driver="ur-sim"), out_dir=tmp_path)
    rec = load(result.path)
    ur = next(c for c in registry.link_faults() if c.field == "skipped_packages")
    data = rec.topic(ur.topic)
    phases = rec.json["/runner/phase"]
    mask = align_mask(data.log_time_ns, np.asarray(phases.log_time_ns, dtype=np.int64),
                      np.array([int(m["phase_id"]) for m in phases.messages]))
    increments = np.diff(data[ur.field].astype(np.int64), prepend=0)
    assert mask.sum() > 50  # the run reached ALIGN and stayed there for a while
    v = check_link(rec)
    assert v.in_align == {ur.name: int(increments[mask].sum())} == {ur.name: int(mask.sum())}
    assert v.trial_valid is False and v.validity.startswith(f"invalid: {int(mask.sum())} ")
