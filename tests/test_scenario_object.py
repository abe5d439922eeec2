"""A new geometry is one scenario module plus a scene: a ball in free flight that the tool
must push 2 cm, judged from the simulator's neutral truth.

The scene file adds the ball as an ``[[objects]]`` entry (a sphere with a named frame
at its centre); the scenario, defined and registered here only, measures the ball
through ``state.truth.bodies`` and ``state.truth.sites`` and records its own measure on
its own topic. Nothing in ffexp or the simulator names the ball or the scenario: the
run goes through ``ffexp run`` on the simulated rig into a real recording.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Literal

import numpy as np
import pytest
from pydantic import Field
from typer.testing import CliRunner

from drivers.base.topics import CdrTopic, FieldSpec, MessageSpec
from drivers.base.types import RobotState, TargetObservation
from ffexp import scenarios
from ffexp.cli import app
from ffexp.estimation import Estimate
from ffexp.recording import load
from ffexp.scenarios import Scenario, ScenarioConfig, SourceChange, Verdict

ROOT = Path(__file__).resolve().parents[1]

PUSHED = MessageSpec("test_msgs/msg/BallPush", (
    FieldSpec("pushed", "float64", 1, "m", "the ball's centre from where it started"),
    FieldSpec("centre", "float64", 3, "m", "the ball's named frame, world"),
), "How far the tool pushed the ball.")


class BallTask(ScenarioConfig):
    scenario: Literal["push_ball"] = "push_ball"
    push_m: float = Field(0.02, gt=0)
    hold_s: float = Field(0.0, ge=0)


class PushBall(Scenario):
    """Push the ball ``push_m`` from where it started; the truth is the only judge."""

    name = "push_ball"
    label = "push a ball"
    config_model = BallTask
    goal = "ball pushed"
    topics = (CdrTopic("/task/push_ball", PUSHED, "every cycle with ground truth"),)

    def __init__(self, config: BallTask) -> None:
        self.config = config
        self.source: str | None = None
        self.start_m: np.ndarray | None = None
        self.pushed = 0.0
        self.centre = np.zeros(3)

    @property
    def hold_s(self) -> float:
        return self.config.hold_s

    def choose_source(self, state: RobotState,
                      target: TargetObservation | None) -> SourceChange | None:
        if self.source is not None:
            return None
        self.source = "truth" if state.truth is not None else "none"
        return SourceChange(self.source, "INFO", f"{self.source} judges the push")

    def observe(self, t_ns: int, state: RobotState, est: Estimate,
                target: TargetObservation | None) -> None:
        if state.truth is None:
            return
        ball = state.truth.bodies["ball"].pose[:3, 3]
        if self.start_m is None:
            self.start_m = ball.copy()
        self.pushed = float(np.linalg.norm(ball - self.start_m))
        self.centre = state.truth.sites["ball.centre"][:3, 3].copy()

    def messages(self) -> list[tuple[str, object]]:
        return [] if self.start_m is None else [("/task/push_ball", self)]

    def holds(self, t_ns: int, state: RobotState, est: Estimate,
              target: TargetObservation | None) -> bool:
        return self.pushed >= self.config.push_m

    def final(self, reached: bool) -> Verdict:
        return Verdict("aligned" if reached else "not aligned", self.source or "none",
                       f"pushed {self.pushed:.3f} m", {"pushed_m": self.pushed}, "", True)


SCENE = """
name = "ball"
[physics]
gravity = 0.0
integrator = "RK4"
[contact]
restitution = 0.05           # a dead ball: the tool follows it (a lively one flies off)
[target]                     # the funnel target, out of the way
support = "free"
lateral = 0.8
[[objects]]
name = "ball"
shape = "sphere"
size = [0.06, 0.06, 0.06]    # m: 6 cm across
mass = 5.0                   # kg: slower after the impact than the 2 cm/s approach
distance = 0.06              # its centre 6 cm ahead of the tool tip: 3 cm to touch
sites = { centre = [0.0, 0.0, 0.0] }
"""

PROTOCOL = """
name = "push_ball"
seed = 1
[scene]
file = "ball.toml"
[task]
scenario = "push_ball"
push_m = 0.02
[run]
timeout_s = 8.0
[align]                      # force control along Z keeps the tool on the ball as it goes
method = "force"
force_axes = [false, false, true, false, false, false]
f_ref = [0.0, 0.0, 1.0, 0.0, 0.0, 0.0]
kp = [0.0, 0.0, 1.0, 0.0, 0.0, 0.0]
ki = [0.0, 0.0, 0.07, 0.0, 0.0, 0.0]
k_ri = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
[estimation.tool_load]
mass_kg = 0.25
gravity_mps2 = 0.0
"""


@pytest.fixture
def registered() -> Iterator[None]:
    scenarios.register(PushBall)
    try:
        yield
    finally:
        scenarios.REGISTRY.pop(PushBall.name, None)
        for callback in scenarios._listeners:
            callback()


def test_a_ball_scene_and_a_ball_scenario_run_through_ffexp_run(
        tmp_path: Path, registered: None) -> None:
    (tmp_path / "ball.toml").write_text(SCENE)
    protocol = tmp_path / "push_ball.toml"
    protocol.write_text(PROTOCOL)
    out = tmp_path / "runs"
    result = CliRunner().invoke(app, ["run", str(protocol), "--out", str(out)])
    assert result.exit_code == 0, result.output  # DONE, the goal reached
    rec = load(next(out.rglob("*.mcap")))
    pushed = rec.topic("/task/push_ball")
    ball = rec.topic("/sim/body/ball")
    assert float(pushed["pushed"][-1]) >= 0.02
    # the scenario's measure is the truth's: the ball's centre moved as its body did (at
    # the scenario's last cycle; the run holds still a moment after its goal)
    at = int(np.searchsorted(ball.log_time_ns, pushed.log_time_ns[-1]))
    path = ball["pose"].reshape(-1, 4, 4)[:, :3, 3]
    moved = path[at] - path[0]
    assert np.linalg.norm(moved) == pytest.approx(float(pushed["pushed"][-1]), abs=1e-9)
    np.testing.assert_allclose(pushed["centre"][-1], path[at], atol=1e-12)
    # pushed along the approach (TCF Z = world +x in the paper pose), and only by contact
    assert moved[0] > 0.015
    assert float(ball["mass_kg"][0]) == pytest.approx(5.0)
    analysis = CliRunner().invoke(app, ["analyze", str(rec.path), "--json"])
    assert analysis.exit_code == 0, analysis.output
    assert json.loads(analysis.output)["first_contact_s"] is not None
