"""``ffexp calibrate`` knows when it is wrong: recordings made in the nominal scene with one
value changed are fitted back within the stated interval, whichever data inform the key
(bed friction with the target at rest until the arm pushes it is informed only after the
first contact), and a fit whose model cannot explain the data says so and writes nothing."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from ffexp.calibrate.run import calibrate
from ffexp.cli import app
from ffexp.experiment import run_file
from ffexp.rig_choice import RigChoice

ROOT = Path(__file__).resolve().parents[1]
PROTOCOL = ROOT / "protocols/method2_f08.toml"
SCENE = ROOT / "data/scenes/paper.toml"
runner = CliRunner()
pytestmark = pytest.mark.slow


def push(out: Path, changed: list[str], seed: int = 1) -> Path:
    """The approach into the funnel from close by and off its axis, the target at rest until
    pushed, in the nominal scene with ``changed`` scene keys (``--set scene.KEY=V``)."""
    sets = [f"scene.{c}" for c in ["target.distance=0.004", "target.lateral=0.028", *changed]]
    return run_file(PROTOCOL, ["run.timeout_s=3.0", f"seed={seed}", *sets],
                    rig=RigChoice(driver="sim"), out_dir=out).path


@pytest.fixture(scope="module")
def recs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    out = tmp_path_factory.mktemp("misfit")
    return {"mu": push(out / "mu", ["target.mu=0.006"]),
            "scale": push(out / "scale", ["arm.friction_scale=0.0012"]),
            "other": push(out / "other", ["arm.friction_scale=0.003"])}


def test_bed_friction_informed_only_after_contact_is_recovered_within_its_interval(
        recs: dict[str, Path]) -> None:
    res, _ = calibrate([recs["mu"]], ["target.mu"], SCENE, jobs=2)
    (est,) = res.estimates
    # the data before the first contact do not inform it: the whole recording is fitted
    assert any("whole runs" in s.name for s in res.stages if s.kept)
    assert est.ci_lo <= 0.006 <= est.ci_hi, (est.value, est.ci_lo, est.ci_hi)
    assert abs(est.value - 0.006) < 0.1 * (0.0085 - 0.006)
    assert res.consistent and res.converged


def test_joint_friction_scale_is_recovered_within_its_interval(recs: dict[str, Path]) -> None:
    res, _ = calibrate([recs["scale"]], ["arm.friction_scale"], SCENE, jobs=2)
    (est,) = res.estimates
    assert est.ci_lo <= 0.0012 <= est.ci_hi, (est.value, est.ci_lo, est.ci_hi)
    assert res.consistent


def test_a_model_that_cannot_explain_the_data_says_so_and_writes_nothing(
        recs: dict[str, Path], tmp_path: Path) -> None:
    # recorded with three times the joint friction; only bed friction may move
    out = tmp_path / "lab.toml"
    args = ["calibrate", str(recs["other"]), "--fit", "target.mu", "--out", str(out)]
    result = runner.invoke(app, args)
    assert result.exit_code == 1, result.stderr
    assert "not consistent with the data" in result.stderr
    assert "noise floor" in result.stderr  # the warning line of the misfit
    assert not out.exists() and not (tmp_path / "lab-report" / "lab.toml").exists()
    # the terminal's tables fit its width (80 columns when piped) ...
    table = [x for x in result.stdout.splitlines() if x[:1] in "┏┃┡│└"]
    assert table and max(len(line) for line in table) <= 80
    # ... and the page shows values, not Python's reprs
    page = (tmp_path / "lab-report" / "calibration.html").read_text()
    assert "not consistent with the data" in page
    # ... and nothing reads "identified": not the terminal, the page or its data
    params = result.stdout.split("residuals (rms")[0]  # the parameters' table
    assert "identi" in params and " NO " in params and " yes " not in params
    with (tmp_path / "lab-report" / "calibration-parameters.csv").open() as f:
        assert {row["identified"] for row in csv.DictReader(f)} == {"NO"}
    data = json.loads((tmp_path / "lab-report" / "calibration.json").read_text())
    assert data["consistent"] is False
    assert not any(e["identified"] for e in data["estimates"])
    assert "['" not in page and ">True<" not in page and ">False<" not in page


def test_an_inconsistent_fit_marks_every_estimate_not_identified() -> None:
    from ffexp.calibrate.result import Estimate, mark_inconsistent

    def est(key: str) -> Estimate:
        return Estimate(key, 0.0, 1.0, 0.0, 2.0, "smooth", "least squares", 0.9, 1.1, True)

    ests = [est("target.mu"), est("arm.friction_scale")]
    mark_inconsistent(ests, [])
    assert all(e.identified for e in ests)  # a consistent fit keeps its labels
    why = "target.mu: the data put it 0.5 from 1, beyond its 95 % half-width 0.1"
    mark_inconsistent(ests, [why])
    assert not any(e.identified for e in ests)
    assert ests[0].note.startswith("not consistent with the data: the data put it 0.5")
    assert ests[1].note.startswith("the fit is not consistent with the data (target.mu:")
