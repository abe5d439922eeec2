"""Was the robot link good enough for a run to count? A pure reading of its recording.

A trial is valid for the link when nothing went wrong on it while the method
was in control (ALIGN): none of the back-end's link-fault counters grew (FRI:
measurements lost, doubled, out of order, rejected or skipped by the runner,
cycles answered late, answers the KRC missed; a UR: data packages skipped),
and the robot was commanding with an acceptable link quality every cycle.
Faults outside ALIGN are reported but do not invalidate the trial. A
recording without a single robot state is "no measurement received" (the
robot never answered), not a missing topic. A recording without the run's end
(:attr:`Recording.complete <ffexp.recording.Recording.complete>` false: a
killed run, recovered, or a cut file) is neither: its trial's validity is
:data:`UNKNOWN`, since what happened after its last record is not known.

Sources (whichever the recording has): the counters every back-end states
(:attr:`Backend.link_faults <drivers.base.backend.Backend.link_faults>`, on its
own topics), ``/robot/state`` (commanding, healthy), ``/runner/phase`` (when
ALIGN was) and ``/events`` (the driver's message when nothing arrived).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from drivers import registry
from drivers.base.backend import LinkCounter
from ffexp.contracts import Phase
from ffexp.recording.reader import Recording

_OUT_OF_CMD = ("not_commanding", "cycles not commanding")
_UNHEALTHY = ("unhealthy", "cycles with unacceptable link quality")
#: The trial validity of a run whose end is not recorded.
UNKNOWN = "unknown: the run ended abnormally"


@dataclass(frozen=True)
class LinkVerdict:
    """The link's verdict on one run (:func:`check_link`)."""

    measured: bool
    """At least one robot state was recorded."""
    valid: bool
    """No link fault while in ALIGN (and a measurement was received)."""
    in_align: dict[str, int] = field(default_factory=dict)
    """Fault counts during ALIGN (only the non-zero ones)."""
    whole_run: dict[str, int] = field(default_factory=dict)
    """Fault counts over the whole run (only the non-zero ones)."""
    align_s: float = 0.0
    """Time spent in ALIGN [s]."""
    message: str = ""
    """Why nothing was measured (the driver's message), when ``measured`` is false."""
    ended: bool = True
    """The recording holds the run's end (else the trial's validity is unknown)."""

    @property
    def trial_valid(self) -> bool | None:
        """Valid, invalid, or None: unknown (the run's end is not recorded)."""
        return self.valid if self.ended or not self.valid else None

    @property
    def validity(self) -> str:
        """``valid``, ``invalid: REASONS`` or :data:`UNKNOWN`, for tables."""
        if self.trial_valid is None:
            return UNKNOWN
        return "valid" if self.valid else "invalid: " + ", ".join(self.reasons())

    def reasons(self) -> list[str]:
        """Why the trial is invalid, one phrase each (empty when valid)."""
        if not self.measured:
            return ["no measurement received"]
        return [f"{n} {_label(k)} during ALIGN" for k, n in self.in_align.items()]

    def text(self) -> str:
        """One line for ``ffexp analyze``."""
        if not self.measured:
            return "link: no measurement received" + (f" ({self.message})" if self.message
                                                       else "")
        rest = ("; whole run: " + ", ".join(f"{n} {_label(k)}"
                                            for k, n in self.whole_run.items())
                if self.whole_run else "; no link fault in the whole run")
        if self.trial_valid is None:
            return f"link: trial validity {UNKNOWN}{rest}"
        if self.valid:
            return f"link: valid trial (no link fault in {self.align_s:.2f} s of ALIGN{rest})"
        return "link: INVALID trial: " + ", ".join(self.reasons()) + rest


def fault_counters() -> tuple[LinkCounter, ...]:
    """The link-fault counters of every registered back-end (:mod:`drivers.registry`)."""
    return registry.link_faults()


def fault_topics() -> tuple[str, ...]:
    """The topics those counters are on (what :func:`check_link` reads besides
    ``/robot/state``, ``/runner/phase`` and ``/events``)."""
    return tuple(dict.fromkeys(c.topic for c in fault_counters()))


def _label(key: str) -> str:
    for c in fault_counters():
        if c.name == key:
            return c.meaning
    for k, label in (_OUT_OF_CMD, _UNHEALTHY):
        if k == key:
            return label
    return key


def align_mask(times_ns: np.ndarray, phase_times_ns: np.ndarray,
               phase_ids: np.ndarray) -> np.ndarray:
    """Which of ``times_ns`` fall in ALIGN, given the phase changes (times and ids)."""
    if phase_times_ns.size == 0:
        return np.zeros(times_ns.shape, dtype=bool)
    k = np.searchsorted(phase_times_ns, times_ns, side="right") - 1
    current = np.where(k >= 0, phase_ids[np.clip(k, 0, None)], int(Phase.CONNECT))
    return np.asarray(current == int(Phase.ALIGN))


def _increments(values: np.ndarray) -> np.ndarray:
    """Per message, how much a cumulative counter grew since the message before."""
    v = values.astype(np.int64).reshape(-1)
    return np.diff(v, prepend=v[:1]) if v.size else v


def _count(into_all: dict[str, int], into_align: dict[str, int], key: str,
           per_msg: np.ndarray, align: np.ndarray) -> None:
    total, during = int(per_msg.sum()), int(per_msg[align].sum())
    if total:
        into_all[key] = total
    if during:
        into_align[key] = during


def check_link(rec: Recording) -> LinkVerdict:
    """The link's verdict on a loaded recording (see the module docstring)."""
    states = rec.topics.get("/robot/state")
    estimates = rec.topics.get("/estimator/state")
    if (states is None or len(states) == 0) and (estimates is None or len(estimates) == 0):
        return LinkVerdict(False, False, message=_link_error(rec), ended=rec.complete)
    phases = rec.json.get("/runner/phase")
    if phases is not None and len(phases):
        p_t = np.asarray(phases.log_time_ns, dtype=np.int64)
        p_id = np.array([int(m.get("phase_id", -1)) for m in phases.messages], dtype=np.int64)
    else:
        p_t = p_id = np.zeros(0, dtype=np.int64)
    whole: dict[str, int] = {}
    align: dict[str, int] = {}
    align_s = 0.0
    masks: dict[str, np.ndarray] = {}
    for counter in fault_counters():
        data = rec.topics.get(counter.topic)
        if data is None or not len(data) or counter.field not in data.fields:
            continue
        if counter.topic not in masks:
            masks[counter.topic] = align_mask(data.log_time_ns, p_t, p_id)
        inc = np.maximum(_increments(data[counter.field]), 0)  # a restart resets a counter
        _count(whole, align, counter.name, inc, masks[counter.topic])
    if states is not None and len(states):
        mask = align_mask(states.log_time_ns, p_t, p_id)
        t = states.log_time_ns.astype(np.int64)
        if t.size > 1:
            dt = np.diff(t, append=t[-1:])
            align_s = float(dt[mask].sum()) * 1e-9
        for key, name in ((_OUT_OF_CMD[0], "commanding"), (_UNHEALTHY[0], "healthy")):
            if name in states.fields:
                bad = (np.asarray(states[name]).reshape(-1) == 0).astype(np.int64)
                first_cmd = np.flatnonzero(bad == 0)
                if name == "commanding" and first_cmd.size:
                    bad[: first_cmd[0]] = 0  # before the first CMD: the link's start-up
                _count(whole, align, key, bad, mask)
    return LinkVerdict(True, not align, align, whole, align_s, ended=rec.complete)


def _link_error(rec: Recording) -> str:
    """The last ERROR event about the link (the driver's reason), if any."""
    events = rec.json.get("/events")
    if events is None:
        return ""
    found = ""
    for msg in events.messages:
        if msg.get("name") == "link" and int(msg.get("level", 0)) >= 4:
            found = str(msg.get("message", ""))
    return found
