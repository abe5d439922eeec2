"""A second scenario through the plug point: a flat plate the tool must touch and press
within a force band for a while, judged by its own judge.

It is defined and registered here only, then runs through the real loop
(:func:`ffexp.loop.run`) on the mock robot and F/T sensor of :mod:`drivers.mock`
into a real recording, with nothing in the loop, the task's phases or the run log
changed for it.
"""

from __future__ import annotations

import json
import math
import tomllib
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Literal

import pytest
from loop_script import cycles
from pydantic import Field, ValidationError

from drivers.base.types import RobotState, TargetObservation
from drivers.mock import MockFtSensor, MockRobot
from ffexp import loop, scenarios
from ffexp.contracts import Phase, RunOutcome, StopReason
from ffexp.errors import ConfigError
from ffexp.estimation import Estimate
from ffexp.protocol import RunProtocol, load_run_protocol
from ffexp.recording import Recorder, load
from ffexp.runlog import RunLog
from ffexp.scenarios import Scenario, ScenarioConfig, SourceChange, Verdict
from ffexp.schemas import schema_text

ROOT = Path(__file__).resolve().parents[1]
START_UTC_NS = 1_700_000_000 * 10**9


class PlateTask(ScenarioConfig):
    """``[task]`` of the flat plate."""

    scenario: Literal["flat_plate"] = "flat_plate"
    force_band_n: tuple[float, float] = (2.0, 4.0)
    hold_s: float = Field(0.5, ge=0)


class FlatPlate(Scenario):
    """Touch the plate and press it with f_z inside the band for ``hold_s``; the contact
    force is the only judge ("plate_force")."""

    name = "flat_plate"
    label = "flat plate"
    config_model = PlateTask
    goal = "plate pressed within the band"

    def __init__(self, config: PlateTask) -> None:
        self.config = config
        self.source: str | None = None
        self.f_z = math.nan
        self.in_band_cycles = 0
        self.out_of_band_cycles = 0

    @property
    def hold_s(self) -> float:
        return self.config.hold_s

    def choose_source(self, state: RobotState,
                      target: TargetObservation | None) -> SourceChange | None:
        if self.source is not None:
            return None
        self.source = "plate_force"
        return SourceChange("plate_force", "INFO", "the contact force judges the press")

    def holds(self, t_ns: int, state: RobotState, est: Estimate,
              target: TargetObservation | None) -> bool:
        lo, hi = self.config.force_band_n
        self.f_z = est.f_z
        ok = lo <= est.f_z <= hi
        if ok:
            self.in_band_cycles += 1
        else:
            self.out_of_band_cycles += 1
        return ok

    def final(self, reached: bool) -> Verdict:
        lo, hi = self.config.force_band_n
        reason = (f"f_z within [{lo}, {hi}] N for {self.hold_s} s" if reached
                  else f"f_z never within [{lo}, {hi}] N for {self.hold_s} s")
        return Verdict("aligned" if reached else "not aligned", "plate_force", reason,
                       {"f_z_n": self.f_z, "in_band_cycles": float(self.in_band_cycles),
                        "out_of_band_cycles": float(self.out_of_band_cycles)}, "", True)


@pytest.fixture
def plate(monkeypatch: pytest.MonkeyPatch) -> Iterator[type[FlatPlate]]:
    """The flat plate registered for one test (the registry as it was afterwards)."""
    monkeypatch.setattr(scenarios, "REGISTRY", dict(scenarios.REGISTRY))
    scenarios.register(FlatPlate)
    yield FlatPlate


def protocol(**task: object) -> RunProtocol:
    return RunProtocol.model_validate({
        "name": "plate", "align": {"method": "force_ri"}, "run": {"timeout_s": 3.0},
        "task": {"scenario": "flat_plate", **task}})


def run(tmp_path: Path, p: RunProtocol, contact_n: Callable[[int], float],
        n: int = 800) -> tuple[RunOutcome, dict[str, list[dict[str, object]]]]:
    """The loop on the mock rig (f_z scripted per cycle) into a recording; the outcome and
    the recording's verdicts and events as JSON."""
    states, fts = cycles(n, contact_n=contact_n)
    path = tmp_path / "plate.mcap"
    with Recorder(path) as rec:
        log = RunLog(rec, START_UTC_NS, p.run.tf_period_s)
        out = loop.run(p, MockRobot(states), MockFtSensor(fts), log)
    recording = load(path)
    got = {topic: list(recording.json[topic].messages)
           for topic in ("/alignment/verdict", "/events")}
    return out, got


def pressing(force_n: float, from_cycle: int = 100) -> Callable[[int], float]:
    return lambda i: force_n if i >= from_cycle else 0.0


def test_the_plate_is_pressed_within_the_band_and_its_judge_says_so(
        tmp_path: Path, plate: type[FlatPlate]) -> None:
    p = protocol(force_band_n=[2.0, 4.0], hold_s=0.5)
    out, got = run(tmp_path, p, pressing(3.0))
    assert out.phase is Phase.DONE and out.stop_reason is StopReason.ALIGNED and out.aligned
    verdicts = got["/alignment/verdict"]
    assert {v["source"] for v in verdicts} == {"plate_force"}
    final = verdicts[-1]
    assert final["final"] and final["label"] == "aligned"
    assert final["evidence"]["f_z_n"] == pytest.approx(3.0, abs=0.2)
    messages = [e["message"] for e in got["/events"]]
    assert "plate pressed within the band (judged by plate_force)" in messages
    assert "the contact force judges the press" in messages
    # the task's phases, as for any scenario
    phases = [m.split(": ")[0] for e in got["/events"] if e["name"] == "phase"
              for m in [e["message"]]]
    assert phases[1:4] == ["CONNECT -> APPROACH", "APPROACH -> ALIGN", "ALIGN -> DONE"]


@pytest.mark.parametrize("force_n", [1.0, 6.0])
def test_a_press_outside_the_band_is_not_the_goal(
        tmp_path: Path, plate: type[FlatPlate], force_n: float) -> None:
    out, got = run(tmp_path, protocol(force_band_n=[2.0, 4.0], hold_s=0.5), pressing(force_n))
    assert out.stop_reason is StopReason.TIMEOUT and not out.aligned
    final = got["/alignment/verdict"][-1]
    assert final["source"] == "plate_force" and final["label"] == "not aligned"
    evidence = final["evidence"]
    assert evidence["in_band_cycles"] == 0 and evidence["out_of_band_cycles"] > 300


def test_leaving_the_band_before_the_hold_restarts_it(
        tmp_path: Path, plate: type[FlatPlate]) -> None:
    """In the band for 0.4 s at a time, out of it for 0.1 s: a hold of 0.5 s never completes,
    although the force is in the band 80 % of the time; a hold of 0.3 s does."""
    def wavering(i: int) -> float:
        return 0.0 if i < 100 else (3.0 if (i - 100) % 100 < 80 else 6.0)

    out, got = run(tmp_path, protocol(hold_s=0.5), wavering)
    assert not out.aligned and got["/alignment/verdict"][-1]["label"] == "not aligned"
    assert got["/alignment/verdict"][-1]["evidence"]["in_band_cycles"] > 300
    out, got = run(tmp_path, protocol(hold_s=0.3), wavering)
    assert out.aligned and got["/alignment/verdict"][-1]["label"] == "aligned"


def test_the_scenario_is_chosen_by_the_protocol_and_only_once_registered(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "plate.toml"
    path.write_text('name = "plate"\n[task]\nscenario = "flat_plate"\nforce_band_n = [1, 2]\n')
    with pytest.raises(ConfigError, match=r"task\.scenario: unknown scenario 'flat_plate'"):
        load_run_protocol(path)
    with pytest.raises(ValidationError, match=r"task\.scenario\n.*unknown scenario"):
        RunProtocol(name="plate", task=PlateTask())  # as an object, too
    monkeypatch.setattr(scenarios, "REGISTRY", dict(scenarios.REGISTRY))
    scenarios.register(FlatPlate)
    p = load_run_protocol(path)
    assert isinstance(p.task, PlateTask) and p.task.force_band_n == (1.0, 2.0)
    assert RunProtocol(name="plate", task=PlateTask()).scenario == "flat_plate"
    assert isinstance(scenarios.build(p), FlatPlate)
    # its own fields, typed; the funnel's [alignment] is not its table
    with pytest.raises(ConfigError, match=r"task\.hold_s: Input should be greater than"):
        load_run_protocol(path, ["task.hold_s=-1"])
    with pytest.raises(ConfigError, match=r"alignment: scenario 'flat_plate' does not read"):
        load_run_protocol(path, ["alignment.hold_s=1"])
    # the dump names the scenario and reads back as it was (replay reads it so)
    again = RunProtocol.model_validate_json(p.model_dump_json())
    assert again == p
    # the schema is generated from the registry
    assert '"flat_plate"' in schema_text("protocol")
    with pytest.raises(ValueError, match="already registered"):
        scenarios.register(type("Other", (FlatPlate,), {}))


@pytest.mark.parametrize(("band", "aligned"), [("[0.6,1.0]", True), ("[2.0,3.0]", False)])
def test_the_plate_on_the_simulator_through_the_experiment_and_the_analysis(
        tmp_path: Path, plate: type[FlatPlate], band: str, aligned: bool) -> None:
    """The same scenario on the sim rig through :func:`ffexp.experiment.run_file`: Method I
    presses the target at f_ref 0.8 N, inside the first band and below the second; the
    recording's analysis reads the plate's judge like any other."""
    from ffexp.analysis import metrics
    from ffexp.experiment import run_file

    result = run_file(ROOT / "protocols/method1_case1.toml",
                      ["task.scenario=flat_plate", f"task.force_band_n={band}",
                       "task.hold_s=0.5", "run.timeout_s=8"], out_dir=tmp_path)
    m = metrics(load(result.path))
    assert m.aligned is aligned and result.outcome.aligned is aligned
    assert m.verdict == ("aligned" if aligned else "not aligned")
    assert m.verdict_source == "plate_force" and m.verdict_truth is None
    assert m.first_contact_s is not None  # the tool did press the target
    lo, hi = json.loads(band)
    assert (lo <= m.verdict_evidence["f_z_n"] <= hi) is aligned  # the last judged press


RUN_PROTOCOLS = [p for p in sorted(ROOT.glob("protocols/*.toml"))
                 if p.read_text().startswith("#:schema ../schemas/protocol.json")]


def test_there_are_shipped_run_protocols() -> None:
    assert len(RUN_PROTOCOLS) >= 5


@pytest.mark.parametrize("path", RUN_PROTOCOLS, ids=lambda p: p.name)
def test_shipped_protocols_dump_as_before_unless_they_name_a_scenario(path: Path) -> None:
    """A shipped protocol without a ``[task]`` table is the funnel alignment, and its dump
    (the recording's ``run.protocol_json``, the sweeps' plan digest) has no ``task``; the
    6-DOF ones name theirs (docking6) and their dump carries it."""
    p = load_run_protocol(path)
    named = tomllib.loads(path.read_text()).get("task", {}).get("scenario")
    assert p.scenario == (named or "funnel_alignment")
    assert ("task" in json.loads(p.model_dump_json())) == (named is not None)
    assert isinstance(scenarios.build(p), scenarios.REGISTRY[p.scenario])


def test_an_unknown_scenario_is_one_error_line_and_exit_2() -> None:
    from typer.testing import CliRunner

    from ffexp.cli import app

    result = CliRunner().invoke(app, ["run", str(ROOT / "protocols/method2.toml"),
                                      "--set", "task.scenario=peg_in_hole"])
    assert result.exit_code == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ")
    assert "task.scenario: unknown scenario 'peg_in_hole'; known: funnel_alignment" in lines[0]
