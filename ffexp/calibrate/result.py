"""What a calibration found: each parameter's estimate, each stage, the whole result."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from ffexp.calibrate.inputs import ReplayInput
from ffexp.calibrate.residuals import Comparison
from ffexp.calibrate.resim import Trace


@dataclass
class Estimate:
    """One fitted parameter."""

    key: str
    start: float
    value: float
    lo: float
    hi: float
    stage: str
    method: str
    ci_lo: float
    ci_hi: float
    identified: bool
    note: str = ""


@dataclass
class StageResult:
    name: str
    method: str
    keys: list[str]
    converged: bool
    evaluations: int
    cost_before: float
    cost_after: float
    note: str = ""
    kept: bool = True
    """False for a profile's fit at a delay that lost (its convergence does not count)."""


@dataclass
class FitResult:
    """Everything a calibration found (JSON data through
    :func:`ffexp.calibrate.report.result_dict`)."""

    values: dict[str, float]
    estimates: list[Estimate]
    stages: list[StageResult]
    converged: bool
    ft_shift: int
    condition: float
    correlation: list[list[float]]
    corr_keys: list[str]
    start: dict[str, list[Comparison]] = field(default_factory=dict)
    """``"fit"``/``"holdout"`` comparisons at the start values, per recording."""
    final: dict[str, list[Comparison]] = field(default_factory=dict)
    traces: dict[str, list[tuple[Trace, Trace]]] = field(default_factory=dict)
    """Per set: (start trace, fitted trace) per recording, for figures and outcomes."""
    rollouts: int = 0
    elapsed_s: float = 0.0
    start_shift: int = 0
    """The F/T delay in samples at the start values."""
    base_scene: dict[str, Any] = field(default_factory=dict)
    """The start scene (JSON data), which the calibrated scene changes."""
    inputs: dict[str, list[ReplayInput]] = field(default_factory=dict)
    """``"fit"``/``"holdout"``: the recordings."""
    consistent: bool = True
    """False: the data put a fitted value outside its interval (the model cannot explain
    them at the result); the reasons are in :attr:`inconsistent`."""
    inconsistent: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    """One line per recording whose F/T residual exceeds twice its noise floor."""


def mark_inconsistent(estimates: list[Estimate], inconsistent: list[str]) -> None:
    """A fit the data contradict identifies nothing: every estimate reads "not identified"
    (in the terminal, the report and the scene's notes), its note says why (the key's own
    reason when the data put that key outside its interval, else the fit's)."""
    if not inconsistent:
        return
    for e in estimates:
        own = [x for x in inconsistent if x.startswith(f"{e.key}: ")]
        why = ("not consistent with the data: " + own[0][len(e.key) + 2:] if own
               else "the fit is not consistent with the data ("
               + "; ".join(inconsistent) + ")")
        e.identified = False
        e.note = why + (f"; {e.note}" if e.note else "")
