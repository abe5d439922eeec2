"""A run's outcome named by what happened, in the paper's words: the one rule (pure).

The campaign table, the report, ``ffexp reproduce``'s claims, ``ffexp limits``
and ``ffexp analyze --json`` (``outcome``) all name a run by :func:`classify`.
Its input is the run's contact history (when contact was made and lost, from
the estimator's contact flag) and how it ended; no I/O.

The rule, in order:

1. A run that did not end normally is shown as that and not scored against the
   paper: ``incomplete`` (the recording was cut), ``stopped`` (a stop request,
   Ctrl-C or SIGTERM), ``aborted`` (a safety limit or a device fault).
2. ``no contact``: the tool never touched.
3. The **first contact's transient** is measured per run, not chosen: it ends
   where the contact settles, at the first re-contact whose hold outlasts the
   time since the first touch (the last hold counts to the run's end). Where no
   hold does, it is the first contact's bounce series: the first break (the
   impact's rebound) and each break after it whose flight (out of contact) is
   shorter than the one before and, from the third break on, whose interval
   from the break before is shorter too, as a rebound losing energy at each
   impact under a steady push does (the flight of a rebound at speed v under a
   push F is 2 m v / F).
4. ``aligned``: seated and the seat kept to the end (no contact lost after it);
   breaks that recurred before the seat are said in the note
   (:attr:`Outcome.kept_breaking` is true for such a run: ``ffexp limits``'
   upper limit is where the contact keeps breaking, as the paper's is).
5. ``contact kept breaking``: at least :data:`KEPT_BREAKING` breaks after the
   transient: the breaks recur, they are not the impact's rebound.
6. ``pushed away``: the run ends out of contact after a last flight longer than
   all its earlier flights together: the chase is not closing.
7. ``held contact, did not slide``: it pressed without seating (a jam); the note
   gives the final lateral and yaw errors when they are known.

A seat that did not last is said in the note
(``seat at 8.22 s not kept``), so an "aligned" verdict beside another outcome
is never left unexplained.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

ALIGNED = "aligned"
KEPT_BREAKING_LABEL = "contact kept breaking"
HELD = "held contact, did not slide"
PUSHED_AWAY = "pushed away"
NO_CONTACT = "no contact"
#: The outcomes a run is scored by against the paper's (a protocol's ``[paper] outcome``).
OUTCOMES: tuple[str, ...] = (ALIGNED, KEPT_BREAKING_LABEL, HELD, PUSHED_AWAY)
INCOMPLETE = "incomplete"
STOPPED = "stopped"
ABORTED = "aborted"
#: Runs shown as what they are and never scored against the paper.
NOT_SCORED: tuple[str, ...] = (INCOMPLETE, STOPPED, ABORTED)
#: The paper's earlier wording, read as the outcome it names.
ALIASES: dict[str, str] = {"did not slide": HELD}
#: From this many breaks after the first contact's transient the contact "kept breaking"
#: (one later break is an event; two are a recurrence).
KEPT_BREAKING = 2
#: Stop reasons (``StopReason.value``) that mean "stopped", not "aborted".
STOP_REASONS = ("stop_requested",)


@dataclass(frozen=True)
class RunFacts:
    """What the rule reads of a run (times in seconds since its first cycle)."""

    made_s: Sequence[float]
    """When contact was made: the first contact, then each re-contact."""
    lost_s: Sequence[float]
    """When contact was lost, after the first contact."""
    end_s: float
    in_contact_at_end: bool
    seated_s: float | None = None
    """When the goal was first held (a DONE aligned, or the ``aligned`` event)."""
    complete: bool = True
    stop_reason: str | None = None
    """``StopReason.value`` of an ABORT (None: DONE, or not recorded)."""
    abort_message: str | None = None
    lateral_error_m: float | None = None
    yaw_error_deg: float | None = None


@dataclass(frozen=True)
class Transient:
    """The first contact's bounce series: its end and how many breaks it holds."""

    end_s: float | None
    """The re-contact closing it (the first contact itself when it holds none; None
    without contact, or when the series' last break was never followed by contact)."""
    breaks: int


@dataclass(frozen=True)
class Outcome:
    label: str
    note: str = ""
    transient: Transient = Transient(None, 0)
    breaks_after_transient: int = 0

    @property
    def kept_breaking(self) -> bool:
        """The contact broke again and again after the first rebound, whatever the end
        (an aligned run's breaks before its seat included)."""
        return kept_breaking(self.label, self.breaks_after_transient)

    @property
    def scored(self) -> bool:
        """Whether the run is compared with the paper's outcome."""
        return self.label not in NOT_SCORED

    def text(self) -> str:
        return f"{self.label} ({self.note})" if self.note else self.label


def kept_breaking(label: str, breaks_after_transient: int) -> bool:
    """Whether a run's contact kept breaking, from its outcome and its breaks after the
    first rebound: "contact kept breaking", or an aligned run whose breaks recurred
    before its seat (:attr:`Outcome.kept_breaking`)."""
    return label == KEPT_BREAKING_LABEL or (
        label == ALIGNED and breaks_after_transient >= KEPT_BREAKING)


def normalize(paper_outcome: str) -> str:
    """A protocol's ``[paper] outcome`` as one of :data:`OUTCOMES` (older wording read)."""
    return ALIASES.get(paper_outcome, paper_outcome)


def agreement(paper_outcome: str | None, ours: Outcome) -> str | None:
    """``yes``/``NO`` against the paper's outcome; ``not scored`` for a run that did not
    end normally; None when the paper gives none."""
    if paper_outcome is None:
        return None
    if not ours.scored:
        return "not scored"
    return "yes" if normalize(paper_outcome) == ours.label else "NO"


def transient(made_s: Sequence[float], lost_s: Sequence[float], end_s: float | None = None
              ) -> Transient:
    """The first contact's transient (module docstring, rule 3): up to the first hold
    that outlasts the time since the first touch (to ``end_s`` for the last one), else
    the bounce series."""
    if not made_s:
        return Transient(None, 0)
    first = made_s[0]
    lost = [t for t in lost_s if t > first]
    for n, t in enumerate(lost):  # the hold that starts at the re-contact after break n
        back = next((m for m in made_s if m > t), None)
        if back is None:
            break
        ends = next((x for x in lost if x > back), end_s)
        if ends is not None and ends - back > back - first:
            return Transient(back, n + 1)
    return bounce_series(made_s, lost_s)


def bounce_series(made_s: Sequence[float], lost_s: Sequence[float]) -> Transient:
    """The first contact's bounce series: the first break and each following one whose
    flight is shorter than the one before (from the third, its interval too)."""
    if not made_s:
        return Transient(None, 0)
    first = made_s[0]
    lost = [t for t in lost_s if t > first]
    # each break's re-contact (the first contact made after it), None if never
    again: list[float | None] = []
    for t in lost:
        nxt = next((m for m in made_s if m > t), None)
        again.append(nxt)
    if not lost:
        return Transient(first, 0)
    n = 1
    while n < len(lost):
        prev_back, back = again[n - 1], again[n]
        if prev_back is None or back is None:
            break
        flight_prev, flight = prev_back - lost[n - 1], back - lost[n]
        shorter = flight < flight_prev
        if n >= 2:  # the intervals between breaks shrink too (the first has none before)
            shorter = shorter and lost[n] - lost[n - 1] < lost[n - 1] - lost[n - 2]
        if not shorter:
            break
        n += 1
    return Transient(again[n - 1], n)


def classify(f: RunFacts) -> Outcome:
    """The run's outcome (module docstring)."""
    seat = f"seat at {f.seated_s:.2f} s" if f.seated_s is not None else ""
    if not f.complete:
        return Outcome(INCOMPLETE, _join(seat, "the recording ends early"))
    if f.stop_reason is not None:
        label = STOPPED if f.stop_reason in STOP_REASONS else ABORTED
        return Outcome(label, _join(f.abort_message or f.stop_reason, seat))
    if not f.made_s:
        return Outcome(NO_CONTACT)
    tr = transient(f.made_s, f.lost_s, f.end_s)
    first = f.made_s[0]
    lost = [t for t in f.lost_s if t > first]
    kept_seat = f.seated_s is not None and not any(t > f.seated_s for t in lost)
    after = lost[tr.breaks:]
    if kept_seat:
        after = [t for t in after if f.seated_s is not None and t <= f.seated_s]
    n_after = len(after)
    breaking = (f"{n_after} breaks after the transient ended at {tr.end_s:.2f} s"
                if tr.end_s is not None else f"{n_after} breaks after the first")
    if kept_seat:  # how the run ended decides first; breaks on the way are said
        return Outcome(ALIGNED, breaking if n_after >= KEPT_BREAKING else "", tr, n_after)
    not_kept = f"{seat} not kept" if seat else ""
    if n_after >= KEPT_BREAKING:
        return Outcome(KEPT_BREAKING_LABEL, _join(breaking, not_kept), tr, n_after)
    if not f.in_contact_at_end and lost:
        flights = [m - t for t, m in zip(lost, f.made_s[1:], strict=False) if m > t]
        last = f.end_s - lost[-1]
        if last > sum(flights):
            return Outcome(PUSHED_AWAY, _join(f"out of contact for the last {last:.1f} s",
                                              not_kept), tr, n_after)
    errors = ""
    if f.lateral_error_m is not None and f.yaw_error_deg is not None:
        errors = (f"lateral {f.lateral_error_m * 1000:+.1f} mm, "
                  f"yaw {f.yaw_error_deg:+.1f} deg at the end")
    return Outcome(HELD, _join(errors, not_kept), tr, n_after)


def _join(*parts: str) -> str:
    return "; ".join(p for p in parts if p)
