"""The outcome rule (:mod:`ffexp.outcome`): a run named by what happened.

First on contact histories written out by hand (each rule on its own), then on
recordings the simulator makes: a jam whose breaks all fall in the first
contact's rebound, and a run whose contact keeps breaking.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from ffexp import outcome as oc
from ffexp.analysis import metrics, paper_row
from ffexp.cli import app
from ffexp.experiment import run_file
from ffexp.recording import load

ROOT = Path(__file__).resolve().parents[1]


def facts(made: list[float], lost: list[float], end: float = 30.0, *,
          in_contact: bool = True, **kw: object) -> oc.RunFacts:
    return oc.RunFacts(made_s=made, lost_s=lost, end_s=end, in_contact_at_end=in_contact,
                       **kw)  # type: ignore[arg-type]


# a decaying rebound: flights 0.575, 0.13, 0.04 s; intervals 0.705, 0.41 s; then held
JAM = ([3.66, 4.36, 4.62, 4.94], [3.785, 4.49, 4.9])


def test_a_decaying_rebound_is_the_first_contacts_transient_and_a_jam_is_held() -> None:
    assert oc.bounce_series(*JAM) == oc.Transient(4.94, 3)
    tr = oc.transient(*JAM, 30.0)
    assert tr.breaks == 3 and tr.end_s == pytest.approx(4.94)
    got = oc.classify(facts(*JAM, lateral_error_m=-0.004, yaw_error_deg=-6.5))
    assert got.label == oc.HELD and got.scored
    assert got.note == "lateral -4.0 mm, yaw -6.5 deg at the end"


def test_the_transient_ends_where_a_hold_outlasts_the_time_since_the_first_touch() -> None:
    """Holds of 0.13, 0.38 and 1.3 s after 0.7, 0.96 and 1.54 s: none settles; the one
    from 7.0 s to the end (23 s after 3.34 s) does, and every break is the transient's."""
    made, lost = [3.66, 4.36, 4.62, 5.2, 7.0], [3.785, 4.49, 5.0, 6.5]
    assert oc.transient(made, lost, 30.0) == oc.Transient(7.0, 4)
    assert oc.classify(facts(made, lost)).label == oc.HELD


def test_where_no_hold_settles_a_flight_that_does_not_shrink_ends_the_transient() -> None:
    """The run ends 0.5 s into its last hold: no hold settles, so the bounce series
    decides; the third flight (0.2 s) is longer than the second (0.13 s), the series
    ends at the second re-contact, and two breaks follow it."""
    made, lost = [3.66, 4.36, 4.62, 5.2, 7.0], [3.785, 4.49, 5.0, 6.5]
    assert oc.transient(made, lost, 7.5) == oc.Transient(4.62, 2)
    got = oc.classify(facts(made, lost, 7.5))
    assert got.label == oc.KEPT_BREAKING_LABEL and got.breaks_after_transient == 2


def test_one_break_after_the_transient_is_an_event_not_a_recurrence() -> None:
    made, lost = [3.66, 4.36, 10.5], [3.785, 10.0]
    assert oc.classify(facts(made, lost)).label == oc.HELD


def test_a_bounce_that_recurs_keeps_breaking_even_with_a_momentary_seat() -> None:
    made = [3.66, 4.2, 4.495, 5.795, 9.565, 9.715, 16.075]
    lost = [3.79, 4.32, 5.685, 9.545, 9.69, 15.14]
    got = oc.classify(facts(made, lost, 40.0, seated_s=8.22))
    assert got.label == oc.KEPT_BREAKING_LABEL
    assert got.transient == oc.Transient(4.495, 2) and got.breaks_after_transient == 4
    assert "seat at 8.22 s not kept" in got.note


def test_a_kept_seat_is_aligned_whatever_rebounds_came_before_it() -> None:
    got = oc.classify(facts(*JAM, end=7.0, seated_s=6.9))
    assert got.label == oc.ALIGNED and got.note == ""
    # the seat not kept, no recurring breaks: held, and the note says so
    got = oc.classify(facts([3.66, 4.36, 8.0], [3.785, 7.5], seated_s=7.0))
    assert got.label == oc.HELD and got.note == "seat at 7.00 s not kept"


def test_a_kept_seat_after_recurring_breaks_is_aligned_and_says_the_breaks() -> None:
    """How the run ended decides (the seat kept); the breaks on the way are its note and
    make it count as breaking for the gain limits."""
    made, lost = [3.66, 4.36, 6.3, 8.0], [3.785, 5.5, 7.5]  # the second flight is longer
    got = oc.classify(facts(made, lost, 9.0, seated_s=8.5))
    assert got.label == oc.ALIGNED and got.kept_breaking
    assert got.note == "2 breaks after the transient ended at 4.36 s"
    assert not oc.classify(facts(*JAM, end=7.0, seated_s=6.9)).kept_breaking


def test_a_first_break_never_followed_by_contact() -> None:
    """The transient has no end (no re-contact): the run is named all the same."""
    assert oc.transient([3.66], [3.8], 4.2) == oc.Transient(None, 1)
    got = oc.classify(facts([3.66], [3.8], 4.2, in_contact=False))
    assert got.label == oc.PUSHED_AWAY and got.note == "out of contact for the last 0.4 s"


def test_pushed_away_needs_a_last_flight_longer_than_all_earlier_ones() -> None:
    assert oc.classify(facts([3.66, 4.36], [3.785, 6.0], 30.0, in_contact=False)
                       ).label == oc.PUSHED_AWAY
    # ended in the middle of a short flight: not pushed away
    assert oc.classify(facts([3.66, 4.36], [3.785, 29.9], 30.0, in_contact=False)
                       ).label == oc.HELD


@pytest.mark.parametrize(("kw", "label"), [
    ({"complete": False}, oc.INCOMPLETE),
    ({"stop_reason": "stop_requested", "abort_message": "SIGTERM"}, oc.STOPPED),
    ({"stop_reason": "force_limit", "abort_message": "force limit: |f| = 61 N"}, oc.ABORTED),
])
def test_a_run_that_did_not_end_normally_is_shown_as_such_and_not_scored(
    kw: dict[str, object], label: str
) -> None:
    got = oc.classify(facts(*JAM, seated_s=4.0, **kw))
    assert got.label == label and not got.scored and "seat at 4.00 s" in got.note
    assert oc.agreement("aligned", got) == "not scored"


def test_agreement_reads_the_papers_earlier_wording() -> None:
    held = oc.classify(facts(*JAM))
    assert oc.agreement("did not slide", held) == "yes"
    assert oc.agreement("aligned", held) == "NO"
    assert oc.agreement(None, held) is None
    assert oc.classify(facts([], [])).label == oc.NO_CONTACT


# -- on recordings the simulator makes ------------------------------------------------
def _run(tmp_path: Path, protocol: str, *sets: str) -> Path:
    return run_file(ROOT / "protocols" / protocol, list(sets), out_dir=tmp_path).path


def test_a_simulated_jam_whose_breaks_all_fall_in_the_rebound_is_held(tmp_path: Path) -> None:
    """Method I case II at the nominal scene: it rebounds more than once after the first
    touch, then presses without seating. Never "contact kept breaking"."""
    rec = load(_run(tmp_path, "method1_case2.toml", "run.timeout_s=9"))
    m = metrics(rec)
    assert m.contact_breaks >= 2  # the kind of run the question is about
    assert m.transient_end_s is not None
    assert all(t <= m.transient_end_s for t in m.break_times_s)
    assert m.outcome == oc.HELD and "yaw" in m.outcome_note
    row = paper_row(rec, m)
    assert row is not None and row["outcome"].startswith(oc.HELD) and row["agree"] == "NO"
    assert row["end"] == "timeout"
    # the same name from the command line
    res = CliRunner().invoke(app, ["analyze", str(rec.path), "--json"])
    assert res.exit_code == 0, res.stderr
    said = json.loads(res.stdout.splitlines()[0])
    assert (said["outcome"], said["outcome_note"]) == (m.outcome, m.outcome_note)


def test_a_simulated_run_whose_contact_keeps_breaking_says_so(tmp_path: Path) -> None:
    """Method I case I with k_xp far above the paper's upper limit (16 against 2): the
    rotational inertia reduction's positive feedback makes the tool bounce again and
    again, and never seat."""
    rec = load(_run(tmp_path, "method1_case1.toml", "run.timeout_s=12",
                    "align.k_ri=[0.0, 0.2, 0.0, 16.0, 0.0, 0.0]"))
    m = metrics(rec)
    assert m.transient_end_s is not None
    later = [t for t in m.break_times_s if m.transient_end_s < t < m.duration_s - 0.2]
    assert len(later) >= oc.KEPT_BREAKING
    assert m.outcome == oc.KEPT_BREAKING_LABEL and m.breaks_after_transient >= len(later)
