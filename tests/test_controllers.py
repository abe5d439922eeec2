"""The controller registry, the protocol's [align] table, and the admittance method."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from loop_script import pose_at

from drivers.base.types import RobotState
from drivers.config import load_model
from ffexp import controllers
from ffexp.controllers.admittance import Admittance, AdmittanceConfig, MassDamper
from ffexp.controllers.base import Approach, ControlContext
from ffexp.controllers.laws import ForceController
from ffexp.errors import ConfigError
from ffexp.estimation import Estimate
from ffexp.protocol import RunProtocol

ROOT = Path(__file__).resolve().parents[1]


def ctx() -> ControlContext:
    return ControlContext(0.005, Approach(RunProtocol(name="x").approach))


def test_every_registered_method_builds_from_its_config() -> None:
    assert set(controllers.REGISTRY) >= {"force_ri", "force", "impedance", "admittance"}
    for name in controllers.REGISTRY:
        p = RunProtocol.model_validate({"name": "x", "align": {"method": name}})
        c = controllers.build_controller(p.align, ctx())
        assert c.name == name and p.method == name
        assert type(p.align) is controllers.REGISTRY[name].config_model


def test_the_align_table_is_the_registrys_config_models() -> None:
    """``[align]``'s union is built from the registry: one schema per registered method,
    and a method name nobody registered is an error naming the known ones."""
    schema = RunProtocol.model_json_schema()
    align = schema["properties"]["align"]
    mapping = align["discriminator"]["mapping"]
    assert sorted(mapping) == sorted(controllers.REGISTRY)
    for name, ref in mapping.items():
        model = controllers.REGISTRY[name].config_model
        assert ref.endswith("/" + model.__name__)
    with pytest.raises(ValueError, match="force_ri"):
        RunProtocol.model_validate({"name": "x", "align": {"method": "nope"}})


def test_force_ri_is_eq_9() -> None:
    p = RunProtocol.model_validate({"name": "x", "align": {"method": "force_ri"}})
    c = controllers.build_controller(p.align, ctx())
    ref = ForceController(p.align, 0.005)  # type: ignore[arg-type]
    rng = np.random.default_rng(1)
    s = RobotState()
    for k in range(50):
        w = rng.normal(size=6)
        got = c.update(k, s, Estimate(wrench=w))
        np.testing.assert_allclose(got, ref.update(w).total)
    # inertia reduction: F*_y = k_yp w_y, T*_x = k_xp w_x
    np.testing.assert_allclose(c.terms.ri[[1, 3]], [0.2 * w[1], 0.5 * w[3]])  # type: ignore[attr-defined]


def test_method_ii_refuses_inertia_reduction() -> None:
    with pytest.raises(ValueError, match="no inertia reduction"):
        RunProtocol.model_validate(
            {"name": "x", "align": {"method": "force", "k_ri": [0, 0.2, 0, 0, 0, 0]}}
        )


def test_unknown_method_is_one_line_naming_the_field(tmp_path: Path) -> None:
    f = tmp_path / "p.toml"
    f.write_text('name = "p"\n[align]\nmethod = "telepathy"\n')
    with pytest.raises(ConfigError) as err:
        load_model(RunProtocol, f)
    assert "align" in str(err.value) and "\n" not in str(err.value)


def test_earlier_files_with_a_top_level_method_still_load(tmp_path: Path) -> None:
    f = tmp_path / "p.toml"
    f.write_text('name = "p"\nmethod = "force"\n[align]\nk_ri = [0, 0, 0, 0, 0, 0]\n')
    p = load_model(RunProtocol, f)
    assert p.method == "force" and type(p.align).__name__ == "ForceConfig"
    p2 = load_model(RunProtocol, ROOT / "protocols/method1_case1.toml", ["method=force_ri"])
    assert p2.method == "force_ri"


def test_every_protocol_in_the_repo_loads() -> None:
    for f in sorted((ROOT / "protocols").glob("*.toml")):
        text = f.read_text()
        if ("[[runs]]" in text or "[model]" in text or "[claims]" in text
                or "[impact]" in text):
            continue  # a campaign, a Section III sweep, a study, an impact (ffexp hil)
        p = load_model(RunProtocol, f)
        assert p.method in controllers.REGISTRY


def test_the_method_name_is_compared_nowhere_outside_the_registry() -> None:
    names = "|".join(controllers.REGISTRY)
    pattern = re.compile(rf"""(==|!=|\bin\b)\s*\(?["']({names})["']|["']({names})["']\s*(==|!=)""")
    offenders = []
    for f in (ROOT / "ffexp").rglob("*.py"):
        if "controllers" in f.parts:
            continue
        for i, line in enumerate(f.read_text().splitlines(), 1):
            if pattern.search(line):
                offenders.append(f"{f.relative_to(ROOT)}:{i}: {line.strip()}")
    assert offenders == []


def test_mass_damper_against_its_closed_form() -> None:
    # semi-implicit Euler of M v' = d - D v: v_k = (v_{k-1} + dt d / M) / (1 + dt D / M),
    # whose fixed point is d / D and whose step response approaches the continuous
    # v(t) = d/D (1 - exp(-D t / M)) as dt -> 0
    m, d_, dt = np.full(6, 2.0), np.full(6, 40.0), 1e-4
    md = MassDamper(m, d_, dt)
    drive = np.array([0.0, 0.0, 0.8, 0.0, 0.0, 0.0])
    x_closed = 0.0
    for k in range(1, 501):
        md.step(drive)
        t = k * dt
    v_closed = 0.8 / 40.0 * (1.0 - np.exp(-40.0 * t / 2.0))
    x_closed = 0.8 / 40.0 * (t - 2.0 / 40.0 * (1.0 - np.exp(-40.0 * t / 2.0)))
    assert md.state.velocity[2] == pytest.approx(v_closed, rel=2e-3)
    assert md.state.displacement[2] == pytest.approx(x_closed, rel=5e-3)
    for _ in range(20000):  # steady state: the exact fixed point
        md.step(drive)
    assert md.state.velocity[2] == pytest.approx(0.8 / 40.0, rel=1e-9)
    assert np.all(md.state.velocity[[0, 1, 3, 4, 5]] == 0.0)


def test_admittance_drive_and_setpoint() -> None:
    cfg = AdmittanceConfig()
    a = Admittance(cfg, ctx())
    s = RobotState(tcp_pose_m=pose_at(0.0))
    a.enter(0, s, Estimate())
    w = np.array([0.5, -0.3, -0.5, 0.02, 0.1, 0.1])  # the tool pushes with f_z = 0.5 N
    drive = a.drive(w)
    # Z: f_ref - f_c = 0.8 - 0.5; Y and rot-X: the measured wrench; X, rot-Y, rot-Z: not axes
    np.testing.assert_allclose(drive, [0.0, -0.3, 0.3, 0.02, 0.0, 0.0])
    out = a.update(5_000_000, s, Estimate(wrench=w))
    # the set-point moved along +Z (TCF) and -Y: the spring pulls the tool that way
    assert out[2] > 0.0 and out[1] < 0.0
    np.testing.assert_array_equal(out[[0, 4, 5]], 0.0)
    sp = a.setpoint()
    offset = pose_at(0.0)[:3, :3].T @ (sp[:3, 3] - pose_at(0.0)[:3, 3])
    np.testing.assert_allclose(offset, a.model.state.displacement[:3])


def test_admittance_protocol_runs_through_the_registry() -> None:
    p = load_model(RunProtocol, ROOT / "protocols/admittance.toml")
    assert controllers.controller_class(p.method) is Admittance
    assert controllers.tracks_force_reference(p.method)
    assert not controllers.tracks_force_reference("impedance")


@pytest.mark.parametrize(("protocol", "one_line"), [
    ("method3_impedance.toml", True), ("method1_case1.toml", False)])
def test_a_break_restarts_the_approach_line_only_where_the_control_mode_switches(
    tmp_path: Path, protocol: str, one_line: bool
) -> None:
    """The paper (sec. V): "for method (iii) there was no switching of control mode", so
    Method III's set-point follows one line from its anchor through every break; the
    force-control methods start a new line from where the tool is when contact is lost."""
    from ffexp.experiment import run_file
    from ffexp.recording import load

    root = Path(__file__).resolve().parents[1]
    proto = load_model(RunProtocol, root / "protocols" / protocol)
    rec = load(run_file(root / "protocols" / protocol, ["run.timeout_s=5"],
                        out_dir=tmp_path).path)
    terms = rec.topic("/control/terms")
    t = (terms.log_time_ns - terms.log_time_ns[0]) / 1e9
    phase, sp = terms["phase"], terms["setpoint"].reshape(-1, 4, 4)
    first = int(np.flatnonzero(phase == 1)[0])
    back = [i for i in range(first + 1, len(phase)) if phase[i] == 1 and phase[i - 1] == 2]
    assert back, "the run must lose contact once for the question to be asked"
    i = back[0] + 1
    # along the approach direction (TCF Z of the anchor): where the one line would be
    z = sp[first, :3, 2]
    travel = float(z @ (sp[i, :3, 3] - sp[first, :3, 3]))
    line = proto.approach.speed_mps * (t[i] - t[first] + 0.005)
    assert bool(abs(travel - line) < 1e-3) is one_line
