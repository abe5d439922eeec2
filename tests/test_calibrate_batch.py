"""``ffexp calibrate --batch N``: rollouts stepped together in batches fit the same numbers.

A fit of the loop's delay (three values replayed in one call) and the bed's friction to
a short glide (tests/calib_recordings.py) is made with the rollouts one at a time and
with them stepped together in batches of up to 4 (one
:class:`~drivers.world.gate.PhysicsGate` per batch): every fitted number, interval and
residual, and every rollout's trace, must be the same bits; so must rollouts of
different candidates in batches on the pool's processes.
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest
from calib_recordings import SCENE, glide
from typer.testing import CliRunner

from drivers.world.gate import PhysicsGate
from ffexp.calibrate.inputs import read_input
from ffexp.calibrate.params import FITTABLE
from ffexp.calibrate.pool import Rollouts
from ffexp.calibrate.resim import Trace, base_scene
from ffexp.calibrate.run import calibrate
from ffexp.cli import app


@pytest.fixture(scope="module")
def rec(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return glide(tmp_path_factory.mktemp("calib_batch") / "glide")


def same_trace(a: Trace, b: Trace) -> bool:
    for name in ("t_s", "pose", "joints", "ft_t_s", "ft", "target", "seated", "in_contact"):
        x, y = getattr(a, name), getattr(b, name)
        if x.shape != y.shape or x.tobytes() != y.tobytes():
            return False
    return a.failed == b.failed


@pytest.mark.slow
def test_batched_rollouts_fit_the_same_numbers(rec: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    widths: list[int] = []
    real = PhysicsGate._dispatch

    def dispatch(self: PhysicsGate, calls: list[object]) -> None:
        widths.append(len(calls))
        real(self, calls)  # type: ignore[arg-type]

    fit = ["fri.command_delay_cycles=0:2", "target.mu=0:0.02"]
    alone, _ = calibrate([rec], fit, SCENE, jobs=1)
    monkeypatch.setattr(PhysicsGate, "_dispatch", dispatch)
    batched, _ = calibrate([rec], fit, SCENE, jobs=1, batch=4)
    assert max(widths) == 3  # the delay's three values were stepped together
    assert batched.values == alone.values
    assert [asdict(e) for e in batched.estimates] == [asdict(e) for e in alone.estimates]
    assert batched.rollouts == alone.rollouts
    assert batched.ft_shift == alone.ft_shift
    for name in ("fit", "holdout"):
        for (s0, f0), (s1, f1) in zip(alone.traces[name], batched.traces[name], strict=True):
            assert same_trace(s0, s1) and same_trace(f0, f1)
        assert [c.rms for c in batched.final[name]] == [c.rms for c in alone.final[name]]


@pytest.mark.slow
def test_rollouts_in_batches_are_the_rollouts_alone(rec: Path) -> None:
    """Candidates that differ, on the pool's processes in batches, and in this process."""
    inp = read_input(rec, base_scene(SCENE), tuple(FITTABLE))
    cands = [(f"target.mu={mu}",) for mu in (0.002, 0.006, 0.0085)]
    with Rollouts([inp], SCENE, jobs=1) as pool:
        ref = pool.run(cands)
    with Rollouts([inp], SCENE, jobs=2, batch=2) as pool:
        got = pool.run(cands)
        assert pool.count == 3
    assert all(same_trace(a[0], b[0]) for a, b in zip(ref, got, strict=True))
    assert not np.array_equal(ref[0][0].target, ref[1][0].target)  # different candidates


def test_cli_batch_option(rec: Path, tmp_path: Path) -> None:
    res = CliRunner().invoke(app, ["calibrate", "--help"])
    assert "--batch" in res.output
    res = CliRunner().invoke(app, ["calibrate", str(rec), "--fit", "target.mu", "--out",
                                   str(tmp_path / "s.toml"), "--batch", "0"])
    assert res.exit_code == 2
    err = [x for x in res.output.splitlines() if x.strip()]
    assert len(err) == 1 and err[0].startswith("error: ") and "--batch" in err[0]
    assert not (tmp_path / "s.toml").exists()
