"""``ffexp calibrate`` as a library call: :func:`calibrate` (recordings in, a result out)."""

from __future__ import annotations

import math
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

from ffexp.calibrate.fit import Calibration, Progress
from ffexp.calibrate.inputs import ReplayInput, read_input, replaying_robot
from ffexp.calibrate.params import FITTABLE, Param, parse_fit
from ffexp.calibrate.pool import Rollouts
from ffexp.calibrate.residuals import compare
from ffexp.calibrate.resim import base_scene, replay_scene_file
from ffexp.calibrate.result import FitResult, mark_inconsistent
from ffexp.errors import ConfigError, InputError


def load_inputs(paths: Sequence[Path], scene: dict[str, object],
                where: str) -> list[ReplayInput]:
    """Read every recording (bad input: one :class:`InputError` naming the file)."""
    seen: set[Path] = set()
    out = []
    for p in paths:
        if p.resolve() in seen:
            raise ConfigError(where, str(p), "the same recording is given twice")
        seen.add(p.resolve())
        out.append(read_input(p, scene, tuple(FITTABLE)))
    return out


#: A recording's F/T residual above this many times its noise floor gets a warning line.
MISFIT_RATIO = 2.0


def misfit_warnings(res: FitResult) -> list[str]:
    """One line per recording (fitted or held out) whose F/T RMS at the result exceeds
    :data:`MISFIT_RATIO` times its sensor's noise floor: the model does not explain it."""
    out = []
    for name, comps in res.final.items():
        for inp, c in zip(res.inputs.get(name, []), comps, strict=True):
            if not (math.isfinite(c.noise_floor_n) and c.noise_floor_n > 0):
                continue
            ratio = c.rms["force"] / c.noise_floor_n
            if not ratio <= MISFIT_RATIO:
                out.append(f"{inp.name} ({name}): F/T residual {c.rms['force']:.3g} N is "
                           f"{ratio:.3g}x its noise floor {c.noise_floor_n:.3g} N "
                           f"(more than {MISFIT_RATIO:g}x)")
    return out


def calibrate(recordings: Sequence[Path], fit: Sequence[str], scene_file: Path, *,
              holdout: Sequence[Path] = (), scene_overrides: Sequence[str] = (),
              jobs: int = 2, progress: Progress | None = None,
              keep_unidentified: bool = False, batch: int = 1) -> tuple[FitResult, list[Param]]:
    """Fit the scene keys ``fit`` (``KEY`` or ``KEY=LO:HI``) to ``recordings``.

    ``jobs`` processes run the rollouts, each stepping up to ``batch`` of them together
    (:class:`~ffexp.calibrate.pool.Rollouts`; the same fit whatever the two).

    ``holdout`` recordings are not fitted to: they are predicted at the result.
    Raises :class:`ConfigError` / :class:`InputError` (exit 2) on bad input.
    """
    if not recordings:
        raise ConfigError("RUN.mcap", "", "no recording to fit")
    try:  # the recordings' robot sets the base scene; the --fit keys are checked first
        robot, unreplayable = replaying_robot([*recordings, *holdout]), None
    except InputError as exc:
        robot, unreplayable = None, exc
    scene = base_scene(scene_file, scene_overrides, robot)
    params = parse_fit(fit, scene)
    if unreplayable is not None:
        raise unreplayable
    fit_in = load_inputs(recordings, scene, "RUN.mcap")
    held = load_inputs(holdout, scene, "--holdout")
    both = {p.resolve() for p in recordings} & {p.resolve() for p in holdout}
    if both:
        raise ConfigError("--holdout", str(sorted(both)[0]), "is also a recording to fit")
    if "ft_sensor.delay_s" in [p.key for p in params] and any(
            i.ft_estimate for i in fit_in):
        raise InputError("ft_sensor.delay_s: the recordings' F/T is the robot's own estimate "
                         f"({next(i.ft_type for i in fit_in if i.ft_estimate)}), which has "
                         "no sensor path to delay")
    sources = {i.ft_type for i in (*fit_in, *held)}
    if len(sources) > 1:
        raise InputError(f"the recordings' F/T sources differ ({', '.join(sorted(sources))}): "
                         "calibrate with recordings of one source at a time")
    period = 1.0 / float(scene["ft_sensor"]["rate"])
    delay_s = float(scene["ft_sensor"]["delay_s"])
    estimated = [i for i in fit_in if i.ft_estimate]
    if estimated:  # the robot's own estimate: one sample a cycle, no delay
        period, delay_s = estimated[0].sim_cycle_s, 0.0
    t0 = time.monotonic()
    all_in = [*fit_in, *held]
    def done(n: int) -> None:
        if progress is not None:
            progress("rollouts", n, None, "replays of a recording")

    with tempfile.TemporaryDirectory() as tmp, Rollouts(
            all_in, replay_scene_file(scene_file, scene, Path(tmp)), jobs, done,
            batch) as pool:
        fit_idx = list(range(len(fit_in)))
        cal = Calibration(fit_in, params, pool, scene_overrides, period, progress,
                          keep_unidentified, fit_idx, delay_s)
        start_values = dict(cal.values)
        if progress:
            progress("start", 0, len(all_in), "replaying at the start values")
        start_rows = pool.run([cal.overrides(start_values)])[0]
        cal.run()
        est, cond, corr, keys = cal.intervals()
        if progress:
            progress("validate", 0, len(all_in), "replaying at the result")
        final_rows = pool.run([cal.overrides(cal.values)])[0]
        shift0 = cal.shift_of(start_values.get("ft_sensor.delay_s"))
        converged = all(s.converged for s in cal.stages if s.kept)
        res = FitResult(values=cal.values, estimates=est, stages=cal.stages,
                        converged=converged, ft_shift=cal.shift,
                        condition=cond, correlation=corr, corr_keys=keys, start_shift=shift0,
                        inputs={"fit": fit_in, "holdout": held}, base_scene=scene)
        for name, lo, hi in (("fit", 0, len(fit_in)), ("holdout", len(fit_in), len(all_in))):
            res.start[name] = [compare(all_in[i], start_rows[i], shift0) for i in range(lo, hi)]
            res.final[name] = [compare(all_in[i], final_rows[i], cal.shift)
                               for i in range(lo, hi)]
            res.traces[name] = [(start_rows[i], final_rows[i]) for i in range(lo, hi)]
        res.rollouts = pool.count
        res.inconsistent = list(cal.inconsistent)
        res.consistent = not res.inconsistent
        mark_inconsistent(res.estimates, res.inconsistent)
        res.warnings = misfit_warnings(res)
    res.elapsed_s = time.monotonic() - t0
    return res, params
