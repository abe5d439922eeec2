"""The free target rendered by a carrier in the simulator's world (``carrier.render_target``,
docs/hil.md): the chaser touches the carrier's mock-up, held to the pose the carrier loop
renders; untouched, the rendered target keeps the scene's drift and tumble (closed form);
the key is refused where there is no free target."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from drivers.carrier.body import rotation_log
from drivers.description.scene import load_scene
from drivers.errors import ConfigError, SimulationError
from drivers.world.world import SimWorld

ROOT = Path(__file__).resolve().parents[1]
ZERO_G = ROOT / "data/scenes/zero-g.toml"
RENDER = ("carrier.render_target=true", "carrier.cycle_s=0.005",
          "ft_sensor.noise_std=[0.0, 0.0]")


def test_untouched_the_rendered_target_drifts_and_turns_as_the_free_body() -> None:
    """After 1 s the mock-up moved ``drift * t`` and turned ``tumble * t`` (about a
    principal axis, so the rate is constant), each within the loop's lag (a few cycles of
    motion); the rendered body itself exactly so."""
    drift, tumble = np.array([0.01, -0.02, 0.005]), np.array([0.0, 0.0, 0.2])
    scene = load_scene(ZERO_G, [*RENDER, f"target.drift_mps={drift.tolist()}",
                                f"target.tumble_radps={tumble.tolist()}", "target.distance=0.3"])
    w = SimWorld(scene)
    assert w.rendered is not None
    body0 = w.last_state.truth.bodies["target"].pose.copy()
    for _ in range(200):  # 1 s
        state = w.step()
    body = state.truth.bodies["target"]
    lag_s = 0.05
    assert np.linalg.norm(body.pose[:3, 3] - body0[:3, 3] - drift) < np.linalg.norm(drift) * lag_s
    # the flange moves once a world cycle: the mock-up's speed about the drift's
    np.testing.assert_allclose(body.twist[:3], drift, atol=np.linalg.norm(drift) * 0.1)
    turned = rotation_log(body.pose[:3, :3] @ body0[:3, :3].T)
    assert np.linalg.norm(turned - tumble) < np.linalg.norm(tumble) * lag_s
    rendered = w.rendered.loop.body
    np.testing.assert_allclose(rendered.velocity_mps, drift, atol=1e-12)
    np.testing.assert_allclose(rendered.position_m, drift * 1.0, atol=1e-9)
    np.testing.assert_allclose(rendered.angular_radps, tumble, atol=1e-12)
    assert w.rendered.hold is None


def test_the_mockup_is_what_the_world_holds_and_the_target_is_rendered() -> None:
    scene = load_scene(ZERO_G, RENDER)
    w = SimWorld(scene)
    target = w.model.body("target")
    assert float(target.mass[0]) == pytest.approx(scene.carrier.mockup_mass_kg)
    assert w.rendered is not None and w.rendered.loop.body.mass_kg == scene.target.mass
    # the truth's target is the rendered body: its momentum is the rendered mass's
    assert w.last_state.truth.bodies["target"].mass_kg == scene.target.mass


def test_render_target_needs_a_free_target() -> None:
    scene = load_scene(ROOT / "data/scenes/paper.toml", RENDER)
    with pytest.raises(ConfigError, match=r"carrier\.render_target"):
        SimWorld(scene)


def test_a_carrier_cycle_off_the_world_cycle_is_refused() -> None:
    scene = load_scene(ZERO_G, ("carrier.render_target=true", "carrier.cycle_s=0.002"))
    with pytest.raises(ConfigError, match=r"carrier\.cycle_s"):
        SimWorld(scene)


def test_a_carrier_hold_stops_the_world_naming_the_device_and_the_cause() -> None:
    """The rendered target leaves the carrier's workspace box: the carrier holds, and the
    world's next cycle raises once, naming the carrier and its cause (the run's driver
    ends the run ABORT with that line); the rendered body then stays where it is."""
    drift = 0.05
    scene = load_scene(ZERO_G, [*RENDER, f"target.drift_mps=[{drift}, 0.0, 0.0]",
                                "target.distance=0.3", "carrier.workspace_m=[0.02, 0.02, 0.02]"])
    w = SimWorld(scene)
    assert w.rendered is not None
    with pytest.raises(SimulationError, match=r"^carrier held at \d+\.\d{3} s: .*workspace"):
        for _ in range(400):  # 2 s: the box's 0.02 m is crossed after about 0.4 s
            w.advance()
    hold = w.rendered.hold
    assert hold is not None and hold.device == "carrier"
    assert hold.t_s == pytest.approx(0.02 / drift, abs=0.05)
    # said once: the world goes on, the rendered body held
    held_at = w.rendered.loop.body.position_m.copy()
    for _ in range(10):
        w.advance()
    np.testing.assert_array_equal(w.rendered.loop.body.position_m, held_at)


def test_a_run_on_a_rendered_target_ends_abort_with_the_carriers_hold_recorded(
        tmp_path: Path) -> None:
    """``ffexp run`` on a rendered target whose carrier holds (the target drifts out of
    the carrier's workspace box): the run ends ABORT at once, its stop names the carrier and
    the cause, and the recording keeps every cycle until then."""
    from ffexp.contracts import Phase, StopReason
    from ffexp.experiment import run_file
    from ffexp.recording import load

    sets = [f"scene.{s}" for s in (*RENDER, "target.drift_mps=[0.05, 0.0, 0.0]",
                                   "carrier.workspace_m=[0.02, 0.02, 0.02]")]
    result = run_file(ROOT / "protocols/sixdof_method1.toml", sets, out_dir=tmp_path)
    out = result.outcome
    assert out.phase == Phase.ABORT and out.stop_reason == StopReason.DRIVER_ERROR
    assert "carrier held at" in out.reason and "workspace" in out.reason
    assert out.duration_s == pytest.approx(0.02 / 0.05, abs=0.1)
    rec = load(result.path, ["/robot/state"])
    cycles = len(rec.topics["/robot/state"])
    assert rec.complete and cycles == out.cycles >= out.duration_s / 0.005 - 2
