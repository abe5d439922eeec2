"""The link's truth in the recording: whole runs over UDP against the stand-in KRC.

Each test runs a protocol against the FRI emulator with one kind of injected
fault (or none at all, or from the wrong address), checks how the run ends,
and checks the driver's counters recorded on ``/robot/link_driver`` against
what the emulator's fault injector did (it logs the sequence number of every
datagram it hit), and the link verdict of :mod:`ffexp.linkcheck`.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from link_harness import LinkRun, emulated_run

from drivers.emulate.faults import FaultSettings
from ffexp.contracts import Phase, StopReason
from ffexp.linkcheck import align_mask, check_link
from ffexp.recording.reader import Recording


def last(rec: Recording) -> dict[str, int]:
    drv = rec.topic("/robot/link_driver")
    return {k: int(v[-1]) for k, v in drv.fields.items() if k != "turnaround_s"}


def cycles(rec: Recording) -> np.ndarray:
    return rec.topic("/robot/state")["cycle"].astype(np.int64).reshape(-1)


def phase_changes(rec: Recording) -> tuple[np.ndarray, np.ndarray]:
    ph = rec.json["/runner/phase"]
    return (np.asarray(ph.log_time_ns, dtype=np.int64),
            np.array([m["phase_id"] for m in ph.messages], dtype=np.int64))


def link_messages(run: LinkRun) -> list[str]:
    return [m["message"] for m in run.rec.json["/events"].messages if m["name"] == "link"]


# --------------------------------------------------------------------------- no measurement


def test_a_silent_robot_is_an_abort_with_a_valid_file_that_says_so(tmp_path: Path) -> None:
    run = emulated_run(tmp_path, [], silent=True, connect_timeout_s=0.3)
    o = run.outcome
    assert o.phase is Phase.ABORT and o.stop_reason is StopReason.NO_MEASUREMENT
    assert o.cycles == 0
    assert re.fullmatch(r"no FRI measurement from 127\.0\.0\.1 on UDP port \d+ within 0\.3 s: "
                        r"received nothing \(.*\)", o.reason), o.reason
    rec = run.rec
    assert rec.complete and "/estimator/state" not in rec.topics
    phases = rec.json["/runner/phase"].messages
    assert phases[-1]["phase"] == "ABORT" and phases[-1]["stop_reason"] == "no_measurement"
    verdict = check_link(rec)
    assert not verdict.measured and not verdict.valid
    assert verdict.reasons() == ["no measurement received"]
    assert verdict.text().startswith("link: no measurement received (no FRI measurement from")


def test_a_robot_at_another_address_is_named_with_its_datagrams(tmp_path: Path) -> None:
    run = emulated_run(tmp_path, [], robot_ip="127.0.0.2", connect_timeout_s=0.3)
    o = run.outcome
    assert o.stop_reason is StopReason.NO_MEASUREMENT
    m = re.search(r"from 127\.0\.0\.2 on UDP port \d+ within 0\.3 s: received (\d+) datagrams? "
                  r"from another address \(last 127\.0\.0\.1:(\d+)\), dropped", o.reason)
    assert m is not None, o.reason
    # the emulator (in lockstep) repeats its first packet until answered: every copy came
    assert int(m.group(1)) >= 1
    assert check_link(run.rec).text().startswith("link: no measurement received")


# --------------------------------------------------------------------------- loss


def check_loss_counters(run: LinkRun) -> None:
    """Recorded ``lost`` = the datagrams the injector dropped before the last recorded
    cycle; the verdict's ALIGN count = those whose gap showed in an ALIGN cycle."""
    rec = run.rec
    seen = cycles(rec)
    dropped = np.array(run.emu.dropped_out_seqs, dtype=np.int64)
    counted = dropped[dropped < seen[-1]]
    got = last(rec)
    assert got["lost"] == counted.size
    assert got["reordered"] == got["duplicates"] == got["foreign"] == got["rejected"] == 0
    assert got["accepted"] + got["lost"] == seen[-1] - seen[0] + 1
    # where each gap showed: the first recorded cycle after the dropped one
    at = np.searchsorted(seen, counted, side="right")
    in_align = align_mask(rec.topic("/robot/state").log_time_ns, *phase_changes(rec))
    verdict = check_link(rec)
    assert verdict.in_align.get("lost", 0) == int(in_align[at].sum())
    assert verdict.whole_run.get("lost", 0) == counted.size
    # every lost measurement is a cycle the KRC saw unanswered
    assert int(rec.topic("/robot/link")["miss_counter"][-1]) >= counted.size
    assert verdict.valid == (not verdict.in_align)


@pytest.mark.slow
@pytest.mark.parametrize("loss", [0.01, 0.05])
def test_light_loss_is_counted_exactly_and_the_run_goes_on(tmp_path: Path, loss: float) -> None:
    run = emulated_run(tmp_path, ["run.timeout_s=5"], faults=FaultSettings(loss=loss, seed=3))
    assert run.outcome.phase is Phase.DONE
    assert run.emu.dropped_out > 0
    check_loss_counters(run)
    assert any("FRI quality PERFECT -> OK" in m for m in link_messages(run))


def test_heavy_loss_ends_command_mode_and_aborts_with_the_faults_counted(tmp_path: Path) -> None:
    run = emulated_run(tmp_path, ["run.timeout_s=5"], faults=FaultSettings(loss=0.2, seed=3))
    o = run.outcome
    assert o.phase is Phase.ABORT and o.stop_reason is StopReason.LINK_BAD
    check_loss_counters(run)
    msgs = link_messages(run)
    assert any(m.startswith("FRI state CMD -> MON") for m in msgs)
    assert any("-> UNACCEPTABLE" in m for m in msgs)
    levels = {m["message"]: m["level"] for m in run.rec.json["/events"].messages}
    assert next(v for k, v in levels.items() if k.startswith("FRI state CMD -> MON")) == 3


# ------------------------------------------------------------- delay, jitter, duplicates


@pytest.mark.slow
def test_jitter_and_duplicates_in_lockstep_change_nothing_but_the_counters(tmp_path: Path) -> None:
    """Lockstep waits for every answer: delayed and doubled datagrams leave the run
    identical to a clean one; the duplicates are counted as the injector made them and
    the KRC's latency shows the delay."""
    # both wait long for an answer: a reference run that missed a cycle to a stall
    # of a loaded machine (the harness's default wait is 20 ms) is not clean
    clean = emulated_run(tmp_path / "a", ["run.timeout_s=3"], lockstep_timeout_s=0.5)
    faults = FaultSettings(delay_s=0.002, jitter_s=0.001, duplicate=0.05, seed=4)
    noisy = emulated_run(tmp_path / "b", ["run.timeout_s=3"], faults=faults,
                         lockstep_timeout_s=0.5)
    assert clean.emu.missed == noisy.emu.missed == 0
    assert noisy.outcome.phase == clean.outcome.phase
    assert noisy.outcome.stop_reason == clean.outcome.stop_reason
    a, b = clean.rec.topic("/robot/state"), noisy.rec.topic("/robot/state")
    np.testing.assert_array_equal(a["tcp_pose"], b["tcp_pose"])
    seen = cycles(noisy.rec)
    dup = np.array(noisy.emu.duplicated_seqs, dtype=np.int64)
    got = last(noisy.rec)
    # a copy arrives after its original was handed on: counted by the next cycle
    assert got["duplicates"] == int((dup < seen[-1]).sum()) > 0
    assert got["lost"] == got["reordered"] == 0
    assert last(clean.rec)["duplicates"] == 0
    latency = noisy.rec.topic("/robot/link")["latency_s"].reshape(-1)
    assert float(latency[-1]) >= 0.002  # every measurement was held back 2 ms or more
    verdict = check_link(noisy.rec)
    assert verdict.whole_run.get("duplicates", 0) == got["duplicates"]


# --------------------------------------------------------------------------- reordering


@pytest.mark.slow
def test_reordered_measurements_are_counted_and_never_lost(tmp_path: Path) -> None:
    """Real time: a held-back measurement (1.5 cycles) is overtaken by the next one; the
    driver drops it as reordered and does not count it lost."""
    # the faults from the first packet: they need not wait for CMD, which needs 100
    # answered cycles in a row (a loaded machine missed one in every 100 of the run's
    # 200 cycles); the driver counts sequence numbers in MON as in CMD
    run = emulated_run(tmp_path, ["run.timeout_s=1"], pacing="realtime",
                       faults=FaultSettings(reorder=0.05, seed=3), faults_from_start=True)
    seen = cycles(run.rec)
    held = np.array(run.emu.reordered_seqs, dtype=np.int64)
    got = last(run.rec)
    assert held.size > 0
    assert got["reordered"] <= int((held < seen[-1]).sum())
    # overtaken unless the emulator itself ran late (a loaded machine)
    assert got["reordered"] > 0 or run.emu.overruns > 0
    # only those still in flight at the last cycle may be counted missing
    in_flight = {int(seen[-1]) - 2, int(seen[-1]) - 1}
    assert got["lost"] <= len(in_flight & {int(h) for h in held})
    assert got["duplicates"] == 0


# --------------------------------------------------------------------------- the verdict alone


def test_check_link_counts_faults_by_the_phase_they_fell_in() -> None:
    """A hand-made recording: 10 cycles, ALIGN from the 4th to the 7th; counters grow
    by known steps, so the verdict's counts are closed forms."""
    from ffexp.recording.reader import JsonData, TopicData

    t = np.arange(10, dtype=np.int64) * 5_000_000 + 10**18
    lost = np.array([0, 1, 1, 1, 3, 3, 4, 4, 6, 6])  # +1 at 1, +2 at 4, +1 at 6, +2 at 8
    late = np.array([0, 0, 0, 0, 0, 1, 1, 1, 1, 1])  # +1 at 5
    zeros = np.zeros(10, dtype=np.int64)
    drv = TopicData(t, {"lost": lost, "deadline_answers": late, "duplicates": zeros})
    krc = TopicData(t, {"miss_counter": np.array([5, 5, 5, 5, 5, 5, 5, 6, 6, 6])})  # +1 at 7
    commanding = np.array([0, 1, 1, 1, 1, 0, 1, 1, 1, 1], dtype=np.uint8)  # out at 5
    state = TopicData(t, {"commanding": commanding, "healthy": np.ones(10, dtype=np.uint8)})
    phases = JsonData(np.array([t[0], t[4], t[8]]), [
        {"phase_id": int(Phase.CONNECT)}, {"phase_id": int(Phase.ALIGN)},
        {"phase_id": int(Phase.DONE)}])
    rec = Recording(Path("x.mcap"), topics={"/robot/link_driver": drv, "/robot/link": krc,
                                            "/robot/state": state},
                    json={"/runner/phase": phases})
    v = check_link(rec)
    assert v.measured and not v.valid
    assert v.in_align == {"lost": 3, "deadline_answers": 1, "krc_missed": 1, "not_commanding": 1}
    assert v.whole_run == {"lost": 6, "deadline_answers": 1, "krc_missed": 1,
                           "not_commanding": 1}  # cycle 0 is before the first CMD
    assert v.align_s == pytest.approx(4 * 0.005)
    assert v.text().startswith("link: INVALID trial: 3 measurements lost during ALIGN, 1 cycles "
                               "answered late (deadline repeat) during ALIGN")
    # the same run without faults in ALIGN is valid and says what happened elsewhere
    drv.fields["lost"] = np.array([0, 1, 1, 1, 1, 1, 1, 1, 1, 2])
    drv.fields["deadline_answers"] = zeros
    krc.fields["miss_counter"] = np.full(10, 5)
    state.fields["commanding"] = np.ones(10, dtype=np.uint8)
    v = check_link(rec)
    assert v.valid and v.in_align == {} and v.whole_run == {"lost": 2}
    assert v.text() == ("link: valid trial (no link fault in 0.02 s of ALIGN; whole run: "
                        "2 measurements lost)")
