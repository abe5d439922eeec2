"""A frame fixed on a free body is recorded once, as its offset in the body, and read back
as the topic it used to be: ``/sim/site/<name>`` from ``/sim/body/<body>`` and
``/sim/attached``. A recording that wrote the frame every cycle (before) reads alike."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from drivers.base.types import AttachedFrame
from drivers.description.scene import load_scene
from drivers.world import bodies
from drivers.world.arm import ArmCommand, ArmMode
from drivers.world.world import SimWorld
from ffexp.experiment import RigChoice, run_file
from ffexp.recording import load
from ffexp.recording.reader import contents

ROOT = Path(__file__).resolve().parents[1]
PROTOCOL = ROOT / "protocols/method1_case1.toml"
MOUTH = "/sim/site/funnel_mouth"


def test_the_offset_from_the_model_gives_the_frame_of_a_tumbling_body() -> None:
    """Tilted, drifting and tumbling target: the mouth by MuJoCo's own kinematics every
    cycle equals the body's pose times the offset built from the model's bodies."""
    scene = load_scene(ROOT / "data/scenes/zero-g.toml", [
        "target.pitch_deg=12.0", "target.drift_mps=[0.01, -0.02, 0.005]",
        "target.tumble_radps=[0.3, -0.2, 0.5]"])
    w = SimWorld(scene)
    hold = ArmCommand(mode=ArmMode.CART_IMPEDANCE, cart_pose_m=w.last_state.tcp_pose_m.copy(),
                      cart_stiffness_npm_nmprad=np.full(6, 100.0),
                      cart_damping_ratio=np.full(6, 0.7), tcp_wrench_n_nm=np.zeros(6))
    fixed = w.last_state.truth.attached["funnel_mouth"]
    assert fixed.body == "target"
    turned = 0.0
    first = w.last_state.truth.bodies["target"].pose.copy()
    for k in range(200):
        truth = w.step(hold if k == 0 else None).truth
        assert truth is not None and truth.attached["funnel_mouth"] is fixed
        np.testing.assert_allclose(fixed.resolve(truth.bodies["target"].pose),
                                   truth.sites["funnel_mouth"], rtol=0, atol=1e-12)
        turned = float(np.arccos(np.clip((np.trace(
            first[:3, :3].T @ truth.bodies["target"].pose[:3, :3]) - 1) / 2, -1, 1)))
    assert turned > 0.1  # it did turn (0.6 rad/s for 1 s)


@pytest.fixture(scope="module")
def two_kinds(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The same run recorded twice: the frame once as its offset (now), and every cycle
    (as before: no frame is attached)."""
    out = tmp_path_factory.mktemp("attached")
    new = run_file(PROTOCOL, ["run.timeout_s=1.5"], rig=RigChoice(driver="sim"),
                   out_dir=out / "new").path
    mp = pytest.MonkeyPatch()
    mp.setattr(bodies.FreeBodies, "attached", lambda self, sites: {})
    try:
        old = run_file(PROTOCOL, ["run.timeout_s=1.5"], rig=RigChoice(driver="sim"),
                       out_dir=out / "old").path
    finally:
        mp.undo()
    return new, old


def test_old_and_new_recordings_read_alike(two_kinds: tuple[Path, Path]) -> None:
    new, old = two_kinds
    a, b = load(new), load(old)
    assert "/sim/attached" in a.json and "/sim/attached" not in b.json
    frames = a.json["/sim/attached"].messages
    assert len(frames) == 1  # once a run
    offset = np.array(frames[0]["frames"]["funnel_mouth"]["offset"]).reshape(4, 4)
    np.testing.assert_array_equal(a.topics[MOUTH].log_time_ns - a.run_start_ns,
                                  b.topics[MOUTH].log_time_ns - b.run_start_ns)
    np.testing.assert_allclose(a.topics[MOUTH]["pose"], b.topics[MOUTH]["pose"],
                               rtol=0, atol=1e-12)
    pose = a.topics["/sim/body/target"]["pose"].reshape(-1, 4, 4)
    np.testing.assert_array_equal(a.topics[MOUTH]["pose"].reshape(-1, 4, 4),
                                  AttachedFrame("target", offset).resolve(pose))
    # every other topic is the same, message for message
    for topic in set(a.topics) - {MOUTH}:
        for name, values in a.topics[topic].fields.items():
            np.testing.assert_array_equal(values, b.topics[topic][name], err_msg=topic)
    # the old file holds the frame as a channel, the new one the offset: 132-byte
    # messages fewer per cycle
    assert new.stat().st_size < old.stat().st_size


def test_a_frame_asked_for_alone_or_from_a_time_on(two_kinds: tuple[Path, Path]) -> None:
    new, _old = two_kinds
    whole = load(new)
    alone = load(new, [MOUTH])
    assert set(alone.topics) == {MOUTH} and not alone.json  # the helpers are dropped
    np.testing.assert_array_equal(alone.topics[MOUTH]["pose"], whole.topics[MOUTH]["pose"])
    later = whole.run_start_ns + 500_000_000  # the offset was written at the first cycle
    part = load(new, [MOUTH], start_ns=later)
    keep = whole.topics[MOUTH].log_time_ns >= later
    np.testing.assert_array_equal(part.topics[MOUTH]["pose"],
                                  whole.topics[MOUTH]["pose"][keep])
    rows = {r["topic"]: r for r in contents(new).rows}
    assert rows[MOUTH]["messages"] == len(whole.topics[MOUTH])
    assert "resolved from /sim/body/target" in rows[MOUTH]["schema"]


def test_a_malformed_offset_is_a_warning(two_kinds: tuple[Path, Path]) -> None:
    from ffexp.recording import attached
    from ffexp.recording.reader import JsonData

    rec = load(two_kinds[0], ["/sim/body/target"])
    rec.json["/sim/attached"] = JsonData(np.array([0]), [{"frames": {"m": {"body": "target",
                                                                           "offset": [1]}}}])
    attached.resolve(rec)
    assert "/sim/site/m" not in rec.topics
    assert any("not a set of attached frames" in w for w in rec.warnings)
    assert attached.sites_of({"/sim/attached": json.dumps({"x": 1}).encode()}) == {}
