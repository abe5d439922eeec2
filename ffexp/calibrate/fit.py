"""The staged fit: timing, sensor, the smooth parameters, contact; intervals and identifiability.

Stages (:mod:`ffexp.calibrate.params`), each starting where the last one ended:

1. ``timing`` (``fri.command_delay_cycles``): every whole number of cycles in
   the bounds is replayed (in parallel) and the one whose arm motion fits best
   is kept. A delay is a whole number of cycles: no gradient exists.
2. ``sensor`` (``ft_sensor.delay_s``): the simulated F/T series shifted by
   each whole number of samples, no rollout.
3. ``smooth``: ``scipy.optimize.least_squares`` (trust-region reflective, box
   constrained) on the scaled residuals, its Jacobian by forward differences
   whose perturbed rollouts run in parallel. Bed friction, the hose and joint
   friction change the measurements smoothly (the arm and the target glide).
4. ``contact``: CMA-ES (``cmaes``) on the summed squared residuals, each
   generation's candidates replayed in parallel; the funnel contact acts
   through impacts whose timing and number jump with its parameters, where
   finite differences mislead a gradient method.

Why not ``mujoco.sysid``: the simulated arm is the KRC's Cartesian impedance
law computed each cycle in Python around MuJoCo (``SimWorld``), so a rollout
is not a plain ``mujoco.rollout`` of one ``MjModel``; and the scene's keys
(restitution, friction scale) map onto model fields through the simulator's
own conversions. The least-squares stage is the same method (box-constrained
Gauss-Newton-type steps on finite-difference Jacobians, rollouts batched).

Before the smooth and contact stages, a Jacobian at the start says which
parameters the recordings excite at all; one they never excite (its column
is zero) is an unidentifiable set: :class:`~ffexp.errors.InputError`, unless
kept (``keep_unidentified``), when it stays at its start value and is
reported with its bounds as its interval.

Windows: a smooth key is fitted to what comes before each recording's first
contact when those data inform it (its 95 % half-width from them alone is
within a tenth of its bounds); else, e.g. bed friction when the target rests
until the arm pushes it, to the whole recordings, where the push and the
glide after it inform it. Contact keys are fitted to the whole recordings.

Intervals: ``s^2 (J^T J)^-1`` at the result, on the data each key was fitted
to (``s^2`` the residuals' variance, misfit included, inflated by
``(1 + rho) / (1 - rho)`` for their lag-one correlation ``rho``), 95 %
(1.96 sigma), never narrower than the black-box optimiser's last step; for
contact parameters they are local only, and never narrower than the
finite-difference step on the key's data (contact events make the whole
recordings' residuals rough below it). The fit is *not consistent with the
data* when the Gauss-Newton step from the result towards the minimum of those
data is longer than a key's interval: the data put the value elsewhere than
the interval says.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from ffexp.calibrate.inputs import ReplayInput, override
from ffexp.calibrate.linear import gauss_newton_step, half_widths
from ffexp.calibrate.params import Param
from ffexp.calibrate.pool import Rollouts
from ffexp.calibrate.residuals import (
    SIGNALS,
    Comparison,
    best_shift,
    compare,
    contact_onset_s,
)
from ffexp.calibrate.resim import Trace
from ffexp.calibrate.result import Estimate, StageResult
from ffexp.errors import InputError

#: Most moves of the delay's profile (each refits the smooth stage at a neighbour).
TIMING_ROUNDS = 4
#: Forward-difference step in unit coordinates (bounds mapped to [0, 1]).
FD_STEP = 1e-3
#: ... on the whole recordings: contact events shift with a key, so the residuals are rough
#: on a small scale; a step this long sees the trend rather than one break's jump.
FD_STEP_CONTACT = 1e-2
#: Whole recordings: the least squares starts from the best of this many points per key.
SCAN_POINTS = 16
#: Least squares: most residual evaluations of the smooth stage.
LSQ_MAX_NFEV = 25
#: CMA-ES: most generations; converged when its step is below this in unit coordinates.
CMA_MAX_GENERATIONS = 40
CMA_TOL = 3e-3
#: ... or when its best cost improved by less than this fraction over this many generations.
CMA_STALL = (1e-3, 5)
CMA_SIGMA0 = 0.1
#: Identified: 95 % half-width within this fraction of the bounds, correlations below.
IDENT_WIDTH = 0.1
IDENT_CORR = 0.98
#: A discrete delay is identified when every other value costs this many times more.
DISCRETE_MARGIN = 1.5
#: A smooth key is fitted before contact when those data alone give it a 95 % half-width
#: within this fraction of its bounds (else on the whole recordings).
FREE_WIDTH = IDENT_WIDTH


Progress = Callable[[str, int, int | None, str], None]
"""``(stage, done, total or None, status)``."""


class Calibration:
    """A staged fit of ``params`` to ``inputs`` (see the module docstring)."""

    def __init__(self, inputs: Sequence[ReplayInput], params: Sequence[Param],
                 pool: Rollouts, base_overrides: Sequence[str], ft_period_s: float,
                 progress: Progress | None = None, keep_unidentified: bool = False,
                 pool_index: Sequence[int] | None = None, ft_delay_s: float = 0.0) -> None:
        self.inputs = list(inputs)
        self.pool_index = list(range(len(inputs)) if pool_index is None else pool_index)
        self.params = list(params)
        self.pool = pool
        self.base = tuple(base_overrides)
        self.ft_period_s = ft_period_s
        self.progress = progress or (lambda *_a: None)
        self.keep = keep_unidentified
        self.values: dict[str, float] = {p.key: p.start for p in self.params}
        self.ft_delay_s = ft_delay_s
        """The start scene's F/T delay (0 for the robot's own estimate, which has none)."""
        self.shift = self.shift_of(self.values.get("ft_sensor.delay_s"))
        self.stages: list[StageResult] = []
        self.notes: dict[str, str] = {}
        self.unexcited: set[str] = set()
        self.margin: dict[str, float] = {}
        self.onset_s = [contact_onset_s(i) for i in self.inputs]
        """Each recording's first contact: the timing and smooth stages fit what comes before."""
        self.best_traces: list[Trace] | None = None
        self.step_floor: dict[str, float] = {}
        """A black-box optimiser's last step per key: no interval is narrower."""
        self.before_contact: dict[str, bool] = {}
        """Per smooth key: fitted to the data before contact (else the whole recordings)."""
        self.inconsistent: list[str] = []

    # -- helpers ---------------------------------------------------------------
    def shift_of(self, delay_s: float | None) -> int:
        """``delay_s`` (``None``: the start scene's) in whole F/T samples."""
        return round((self.ft_delay_s if delay_s is None else delay_s) / self.ft_period_s)

    def overrides(self, values: dict[str, float]) -> tuple[str, ...]:
        by_key = {p.key: p for p in self.params}
        return (*self.base, *(override(k, by_key[k].value(v)) for k, v in values.items()
                              if k != "ft_sensor.delay_s"))

    def traces(self, candidates: Sequence[dict[str, float]],
               which: Sequence[int] | None = None) -> list[list[Trace]]:
        return self._run([self.overrides(c) for c in candidates], which)

    def _run(self, candidates: Sequence[tuple[str, ...]],
             which: Sequence[int] | None = None) -> list[list[Trace]]:
        """The pool's traces of the fitted recordings ``which`` (default: all)."""
        idx = self.pool_index if which is None else [self.pool_index[i] for i in which]
        return self.pool.run(candidates, idx)

    def comparisons(self, traces: Sequence[Trace], which: Sequence[int] | None = None,
                    signals: Sequence[str] = SIGNALS, free: bool = False) -> list[Comparison]:
        """Each trace against its recording; ``free``: only before the recorded contact."""
        idx = range(len(self.inputs)) if which is None else which
        return [compare(self.inputs[i], t, self.shift, signals,
                        self.onset_s[i] if free else math.inf)
                for i, t in zip(idx, traces, strict=True)]

    def residual(self, traces: Sequence[Trace], which: Sequence[int] | None = None,
                 signals: Sequence[str] = SIGNALS, free: bool = False) -> np.ndarray:
        return np.concatenate([c.residual for c in self.comparisons(traces, which, signals,
                                                                     free)])

    def _with(self, params: Sequence[Param], u: np.ndarray) -> dict[str, float]:
        vals = dict(self.values)
        for p, ui in zip(params, u, strict=True):
            vals[p.key] = p.from_unit(float(ui))
        return vals

    def jacobian(self, params: Sequence[Param], values: dict[str, float],
                 r0: np.ndarray, which: Sequence[int] | None = None,
                 free: bool = False) -> np.ndarray:
        """Forward differences of the scaled residuals in unit coordinates."""
        u0 = np.array([p.to_unit(values[p.key]) for p in params])
        cands, steps = [], []
        fd = FD_STEP if free else FD_STEP_CONTACT
        for i, p in enumerate(params):
            h = fd if u0[i] + fd <= 1.0 else -fd
            u = u0.copy()
            u[i] += h
            vals = dict(values)
            vals[p.key] = p.from_unit(float(u[i]))
            cands.append(vals)
            steps.append(h)
        rows = self._run([self.overrides(c) for c in cands], which)
        cols = [(self.residual(tr, which, free=free) - r0) / h
                for tr, h in zip(rows, steps, strict=True)]
        return np.column_stack(cols) if cols else np.zeros((len(r0), 0))

    def jacobians(self, params: Sequence[Param], values: dict[str, float], by_window: bool = False,
                  ) -> dict[bool, tuple[np.ndarray, np.ndarray]]:
        """``{free: (J, r0)}`` before contact (``True``) and on the whole recordings
        (``False``), from one set of rollouts; ``by_window``: each key's step is the one of
        the data it is fitted to."""
        base = self.traces([values])[0]
        u0 = np.array([p.to_unit(values[p.key]) for p in params])
        cands, steps = [], []
        for i, p in enumerate(params):
            fd = FD_STEP if not by_window or self.before_contact.get(p.key, False) \
                else FD_STEP_CONTACT
            h = fd if u0[i] + fd <= 1.0 else -fd
            cands.append({**values, p.key: p.from_unit(float(u0[i] + h))})
            steps.append(h)
        rows = self.traces(cands)
        out = {}
        for free in (True, False):
            r0 = self.residual(base, free=free)
            cols = [(self.residual(tr, free=free) - r0) / h
                    for tr, h in zip(rows, steps, strict=True)]
            out[free] = (np.column_stack(cols) if cols else np.zeros((len(r0), 0)), r0)
        return out

    # -- stages ----------------------------------------------------------------
    def run(self) -> None:
        """The stages: which parameters are excited at all; the delay over its whole range,
        the smooth stage, the delay's profile (a smooth fit per neighbouring delay); the
        F/T delay; contact (with the F/T delay profiled per candidate); the F/T delay at
        the result."""
        continuous = [p for p in self.params if p.stage in ("smooth", "contact")]
        if continuous:
            self._check_excited(continuous)
        self._timing()
        cost = self._smooth()
        timing = [p for p in self.params if p.stage == "timing"]
        if timing and cost is not None:
            self._profile(timing[0], cost)
        self.best_traces = None
        self._sensor()
        if self._contact():
            self.best_traces = None
            self._sensor()

    def _profile(self, p: Param, cost: float) -> None:
        """The delay and the smooth parameters trade off (both shape the arm's response), so
        each neighbouring delay gets its own smooth fit and the delay whose fit is best wins
        (a profile of the cost over the delay), until the best has no better neighbour."""
        fits: dict[int, tuple[float, dict[str, float], int]] = {
            int(self.values[p.key]): (cost, dict(self.values), len(self.stages) - 1)}
        for _ in range(TIMING_ROUNDS):
            now = min(fits, key=lambda d: fits[d][0])
            for d in (now - 1, now + 1):
                if p.lo <= d <= p.hi and d not in fits:
                    self.values = {**fits[now][1], p.key: float(d)}
                    c = self._smooth()
                    fits[d] = (math.inf if c is None else c, dict(self.values),
                               len(self.stages) - 1)
            best = min(fits, key=lambda d: fits[d][0])
            self.values = dict(fits[best][1])
            if best == now:
                break
        best = int(self.values[p.key])
        for d, (_c, _v, idx) in fits.items():
            if d != best:
                self.stages[idx].kept = False
                self.stages[idx].note += "; not kept: another delay fits better"
        others = [c for d, (c, _v, _i) in fits.items() if d != best]
        self.margin[p.key] = min(others) / max(fits[best][0], 1e-300) if others else math.inf
        listed = ", ".join(f"{d}: {fits[d][0]:.3g}" for d in sorted(fits))
        self.notes[p.key] = f"profiled (smooth stage refitted per value), cost {listed}"

    def _timing(self) -> None:
        ps = [p for p in self.params if p.stage == "timing"]
        if not ps:
            return
        p = ps[0]
        grid = list(range(int(p.lo), int(p.hi) + 1))
        self.progress("timing", 0, len(grid) * len(self.inputs), p.key)
        cands = [{**self.values, p.key: float(d)} for d in grid]
        rows = self._run([self.overrides(c) for c in cands])
        costs = {d: float(sum(c.cost for c in self.comparisons(tr, signals=(
            "tcp", "joints", "target"), free=True))) for d, tr in zip(grid, rows, strict=True)}
        best = min(costs, key=lambda d: costs[d])
        before = costs.get(round(p.start), math.nan)
        self.values[p.key] = float(best)
        others = [c for d, c in costs.items() if d != best]
        margin = min(others) / max(costs[best], 1e-300) if others else math.inf
        listed = ", ".join(f"{d}: {c:.3g}" for d, c in costs.items())
        self.notes[p.key] = f"replayed, cost per value {listed}"

        self.stages.append(StageResult("timing", "exhaustive (integer)",
                                       [p.key], True,
                                       len(grid), before, costs[best],
                                       f"next best costs {margin:.3g}x"))
        self.margin[p.key] = margin
        self.best_traces = rows[grid.index(best)]

    def _sensor(self) -> None:
        ps = [p for p in self.params if p.stage == "sensor"]
        if not ps:
            return
        p = ps[0]
        traces = self.best_traces
        if traces is None:
            self.progress("sensor", 0, len(self.inputs), p.key)
            traces = self.traces([self.values])[0]
        shifts = self._shifts(p)
        lo, hi = shifts.start, shifts.stop - 1
        before = sum(c.cost for c in self.comparisons(traces, signals=("force", "torque")))
        best, costs = best_shift(self.inputs, traces, lo, hi)
        self.shift = best
        self.values[p.key] = best * self.ft_period_s
        others = [c for s, c in costs.items() if s != best]
        margin = min(others) / max(costs[best], 1e-300) if others else math.inf
        self.margin[p.key] = margin
        self.notes[p.key] = f"shift of the simulated F/T series: {best} sample(s)"
        self.stages.append(StageResult("sensor", "exhaustive shift (whole samples)", [p.key],
                                       True, len(costs), before, costs[best],
                                       f"next best costs {margin:.3g}x"))

    def _shifts(self, p: Param) -> range:
        """The F/T delays in whole samples within ``p``'s bounds."""
        return range(math.ceil(p.lo / self.ft_period_s - 1e-9),
                     math.floor(p.hi / self.ft_period_s + 1e-9) + 1)

    def _shift_cost(self, traces: Sequence[Trace], which: Sequence[int]) -> tuple[float, int]:
        """The cost of ``traces`` at the F/T delay that fits them best, if that delay is
        fitted (a shift of the simulated series, no rollout), else at the current one.
        The contact's F/T transients and the delay are fitted together this way: a delay
        chosen before contact is fitted would be chosen against the wrong impacts."""
        sensor = [p for p in self.params if p.stage == "sensor"]
        if not sensor:
            return float(np.sum(self.residual(traces, which) ** 2)), self.shift
        p = sensor[0]
        keep = self.shift
        best = (math.inf, keep)
        try:
            for shift in self._shifts(p):
                self.shift = shift
                c = float(np.sum(self.residual(traces, which) ** 2))
                best = min(best, (c, shift))
        finally:
            self.shift = keep
        return best

    def _check_excited(self, params: list[Param]) -> None:
        self.progress("check", 0, (len(params) + 1) * len(self.inputs), "excitation")
        jacs = self.jacobians(params, self.values)
        jac = jacs[False][0]
        for p, col in zip(params, jac.T, strict=True):
            if not np.any(np.abs(col) > 1e-12):
                self.unexcited.add(p.key)
        # which data inform each smooth key: before contact if those alone pin it down
        jf, rf = jacs[True]
        for i, p in enumerate(params):
            if p.stage == "smooth":
                h = half_widths(jf[:, [i]], rf)[0][0] if rf.size else math.inf
                self.before_contact[p.key] = bool(h <= FREE_WIDTH)
        if self.unexcited and not self.keep:
            names = ", ".join(sorted(self.unexcited))
            raise InputError(f"unidentifiable: no recording excites {names} (its replay does "
                             "not change any recorded signal); add recordings that do, drop it "
                             "from --fit, or --keep-unidentified")

    def _smooth(self) -> float | None:
        """The smooth stage: the keys the data before contact inform, fitted to those data,
        then the others to the whole recordings; its final cost (``None``: nothing to fit)."""
        ps = [p for p in self.params if p.stage == "smooth" and p.key not in self.unexcited]
        if not ps:
            return None
        total = 0.0
        for free in (True, False):
            group = [p for p in ps if self.before_contact.get(p.key, True) == free]
            if group:
                total += self._least_squares(group, free)
        return total

    def _scan(self, ps: list[Param], free: bool, u0: np.ndarray,
              cache: dict[bytes, np.ndarray]) -> np.ndarray:
        """The best of ``u0`` and a space-filling sample of the bounds (Sobol', at least
        :data:`SCAN_POINTS` per key), each replayed once, in parallel: over whole
        recordings a key moves contact events, and the cost has local minima where a break
        comes or goes, so a local method must start in the right basin."""
        from scipy.stats import qmc

        m = math.ceil(math.log2(SCAN_POINTS * len(ps)))
        units = [u0, *qmc.Sobol(len(ps), scramble=False).random_base2(m)]
        self.progress("scan", 0, len(units) * len(self.inputs), "sample of the bounds")
        rows = self.traces([self._with(ps, u) for u in units])
        best, best_c = u0, math.inf
        for u, tr in zip(units, rows, strict=True):
            r = self.residual(tr, free=free)
            cache[np.asarray(u, dtype=float).tobytes()] = r
            if float(r @ r) < best_c:
                best, best_c = np.asarray(u, dtype=float), float(r @ r)
        return best

    def _least_squares(self, ps: list[Param], free: bool) -> float:
        """Least squares of ``ps`` on the data before contact (``free``) or all of them."""
        from scipy.optimize import least_squares

        cache: dict[bytes, np.ndarray] = {}
        evals = [0]

        def fun(u: np.ndarray) -> np.ndarray:
            key = u.tobytes()
            if key not in cache:
                cache[key] = self.residual(self.traces([self._with(ps, u)])[0], free=free)
                evals[0] += 1
                cost = float(cache[key] @ cache[key])
                self.progress("smooth", evals[0], LSQ_MAX_NFEV, f"cost {cost:.4g}")
            return cache[key]

        def jac(u: np.ndarray) -> np.ndarray:
            return self.jacobian(ps, self._with(ps, u), fun(u), free=free)

        u0 = np.array([p.to_unit(self.values[p.key]) for p in ps])
        r0 = fun(u0)
        start = u0 if free else self._scan(ps, free, u0, cache)
        res = least_squares(fun, start, jac=jac, bounds=(0.0, 1.0), method="trf",
                            x_scale="jac", max_nfev=LSQ_MAX_NFEV, xtol=1e-4, ftol=1e-4,
                            gtol=1e-10)
        for p, ui in zip(ps, res.x, strict=True):
            self.values[p.key] = p.from_unit(float(ui))
        ok = bool(res.status > 0)
        delay = self.values.get("fri.command_delay_cycles")
        self.stages.append(StageResult(
            f"smooth{'' if free else ' (whole runs)'}, delay "
            f"{'-' if delay is None else f'{delay:g}'}",
            "least squares (scipy trf, finite-difference Jacobian)",
            [p.key for p in ps], ok, evals[0], float(r0 @ r0), float(2 * res.cost),
            str(res.message)))
        return float(2 * res.cost)

    def _contact(self) -> bool:
        """The contact stage; ``False`` if it has nothing to fit."""
        from cmaes import CMA  # type: ignore[import-untyped]

        ps = [p for p in self.params if p.stage == "contact" and p.key not in self.unexcited]
        if not ps:
            return False
        u0 = np.array([p.to_unit(self.values[p.key]) for p in ps])
        jobs = self.pool.jobs
        popsize = max(4, 4 + int(3 * math.log(len(ps))))
        popsize += (-popsize) % jobs
        cma = CMA(mean=u0, sigma=CMA_SIGMA0, bounds=np.array([[0.0, 1.0]] * len(ps)),
                  population_size=popsize, seed=0)

        touched = [i for i, t in enumerate(self.onset_s) if math.isfinite(t)]

        def costs(us: list[np.ndarray]) -> list[float]:
            rows = self.traces([self._with(ps, u) for u in us], touched)
            return [self._shift_cost(tr, touched)[0] for tr in rows]

        before = costs([u0])[0]
        best_u, best_c = u0, before
        converged = False
        gen = 0
        history: list[float] = []
        for gen in range(1, CMA_MAX_GENERATIONS + 1):
            us = [cma.ask() for _ in range(cma.population_size)]
            cs = costs(us)
            cma.tell(list(zip(us, cs, strict=True)))
            i = int(np.argmin(cs))
            if cs[i] < best_c:
                best_u, best_c = us[i], cs[i]
            self.progress("contact", gen, CMA_MAX_GENERATIONS, f"best cost {best_c:.4g}")
            history.append(best_c)
            step = float(cma._sigma * math.sqrt(float(np.max(np.diag(cma._C)))))
            tol, gens = CMA_STALL
            stalled = len(history) > gens and history[-gens - 1] - best_c <= tol * best_c
            if step < CMA_TOL or stalled or cma.should_stop():
                converged = step < CMA_TOL or stalled
                break
        steps = cma._sigma * np.sqrt(np.diag(cma._C))
        for p, ui, st in zip(ps, best_u, steps, strict=True):
            self.values[p.key] = p.from_unit(float(ui))
            self.step_floor[p.key] = float(st) * (p.hi - p.lo)
        self.stages.append(StageResult(
            "contact", f"CMA-ES (cmaes, population {popsize})", [p.key for p in ps], converged,
            gen * popsize, before, best_c,
            f"{gen} generation(s)" + ("" if converged else "; step still large: not converged")))
        return True

    # -- result ----------------------------------------------------------------
    def intervals(self) -> tuple[list[Estimate], float, list[list[float]], list[str]]:
        """Each parameter's value, 95 % interval and identifiability at the result, from the
        data it was fitted to; :attr:`inconsistent` names the keys those data put outside their
        interval."""
        cont = [p for p in self.params if p.stage in ("smooth", "contact")]
        fitted = [p for p in cont if p.key not in self.unexcited]
        est: list[Estimate] = []
        cond, corr = math.nan, np.zeros((0, 0))
        half: dict[str, float] = {}
        maxcorr: dict[str, float] = {}
        if fitted:
            self.progress("intervals", 0, (len(fitted) + 1) * len(self.inputs), "")
            jacs = self.jacobians(fitted, self.values, by_window=True)
            scale = np.array([p.hi - p.lo for p in fitted])
            jp = jacs[False][0] / scale  # physical units, whole recordings
            jtj = jp.T @ jp
            norms = np.sqrt(np.diag(jtj))
            safe = np.where(norms > 0, norms, 1.0)
            sv = np.linalg.svd(jtj / np.outer(safe, safe), compute_uv=False)
            cond = float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf
            corr = np.zeros((len(fitted), len(fitted)))
            for free in (True, False):
                idx = [i for i, p in enumerate(fitted)
                       if self.before_contact.get(p.key, False) == free]
                if not idx:
                    continue
                jw, rw = jacs[free][0][:, idx] / scale[idx], jacs[free][1]
                hw, cov = half_widths(jw, rw)
                step = gauss_newton_step(jw, rw)
                sd = np.sqrt(np.clip(np.diag(cov), 0, None))
                denom = np.where(sd > 0, sd, 1.0)
                sub = cov / np.outer(denom, denom)
                for a, i in enumerate(idx):
                    p = fitted[i]
                    # never finer than the method resolves: its difference step or last step
                    fd = (FD_STEP if free else FD_STEP_CONTACT) * (p.hi - p.lo)
                    h = max(float(hw[a]), self.step_floor.get(p.key, 0.0), fd)
                    half[p.key] = h
                    corr[i, idx] = sub[a]
                    maxcorr[p.key] = max((abs(sub[a, b]) for b in range(len(idx)) if b != a),
                                         default=0.0)
                    far = abs(float(step[a]))
                    if math.isfinite(h) and far > h:
                        self.inconsistent.append(
                            f"{p.key}: the data put it {far:.3g} from {self.values[p.key]:.6g}, "
                            f"beyond its 95 % half-width {h:.3g}")
        for p in self.params:
            v = self.values[p.key]
            method = {"timing": "exhaustive", "sensor": "exhaustive shift",
                      "smooth": "least squares", "contact": "CMA-ES"}[p.stage]
            if p.stage in ("timing", "sensor"):
                margin = self.margin.get(p.key, math.inf)
                ok = bool(margin >= DISCRETE_MARGIN)
                est.append(Estimate(p.key, p.start, v, p.lo, p.hi, p.stage, method,
                                    v if ok else p.lo, v if ok else p.hi, ok,
                                    self.notes.get(p.key, "")
                                    + ("" if ok else f"; other values fit almost as well "
                                       f"({margin:.3g}x)")))
                continue
            if p.key in self.unexcited:
                est.append(Estimate(p.key, p.start, v, p.lo, p.hi, p.stage, "kept", p.lo, p.hi,
                                    False, "no recording excites it: kept at its start value"))
                continue
            h = half[p.key]
            lo, hi = max(p.lo, v - h), min(p.hi, v + h)
            ok = bool(h <= IDENT_WIDTH * (p.hi - p.lo) and maxcorr[p.key] < IDENT_CORR)
            note = "" if ok else (f"weakly identified: 95 % half-width {h:.3g}, "
                                  f"largest correlation {maxcorr[p.key]:.3f}")
            est.append(Estimate(p.key, p.start, v, p.lo, p.hi, p.stage, method, lo, hi, ok,
                                note))
        return est, cond, corr.tolist(), [p.key for p in fitted]

