"""The rig's 3-D scene: forward kinematics against MuJoCo, and the scene in a recording
read back with the ``mcap`` reader and ``json`` alone, its poses checked against ``/tf``."""

from __future__ import annotations

import json
import math
from collections import defaultdict
from pathlib import Path

import jsonschema
import mujoco
import numpy as np
import pytest
from mcap.reader import make_reader

from drivers.description.scene import Scene, load_scene
from drivers.world.mjcf import build_xml
from ffexp.experiment import RigChoice, run_file
from ffexp.scene3d.kinematics import chain, link_transforms, tcp_pose

ROOT = Path(__file__).resolve().parents[1]


def _mujoco_tcp(scene: Scene, q: np.ndarray) -> np.ndarray:
    """The TCP site of the simulator's own arm model at joint positions ``q``."""
    model = mujoco.MjModel.from_xml_string(build_xml(scene, None))
    data = mujoco.MjData(model)
    data.qpos[:len(q)] = q
    mujoco.mj_kinematics(model, data)
    site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, "tcp")
    out = np.eye(4)
    out[:3, :3] = data.site_xmat[site].reshape(3, 3)
    out[:3, 3] = data.site_xpos[site]
    return out


@pytest.mark.parametrize("scene_file", ["paper.toml", "paper-ur5e.toml"])
@pytest.mark.parametrize("base_pos", [(0.0, 0.0, 0.0), (0.1, -0.2, 0.05)])
def test_forward_kinematics_agrees_with_the_simulators_arm(base_pos: tuple[float, ...],
                                                           scene_file: str) -> None:
    scene = load_scene(ROOT / "data/scenes" / scene_file, [f"arm.base_pos={list(base_pos)}"])
    arm = scene.arm.description
    limits = np.radians(arm.position_limits_deg)
    rng = np.random.default_rng(5)
    for q in [np.array(scene.arm.q_init), *rng.uniform(-limits, limits, (12, arm.joints))]:
        np.testing.assert_allclose(tcp_pose(scene, q), _mujoco_tcp(scene, q), atol=1e-12)


def test_link_transforms_reject_fewer_joint_positions_than_the_arm_has() -> None:
    from drivers.description import UR5E

    with pytest.raises(ValueError, match="6 joint positions; the KUKA LWR4\\+ has 7"):
        link_transforms(np.zeros(6))
    with pytest.raises(ValueError, match="5 joint positions; the UR5e has 6"):
        link_transforms(np.zeros(5), arm=UR5E)


def test_a_joint_turns_the_links_after_it_about_its_axis() -> None:
    """Joint 1 turns about the base z axis: every link's origin turns with it."""
    q = np.array([0.0, 0.4, 0.2, -1.1, 0.3, 0.7, 0.0])
    turned = q.copy()
    turned[0] = 0.5
    rz = np.array([[math.cos(0.5), -math.sin(0.5), 0], [math.sin(0.5), math.cos(0.5), 0],
                   [0, 0, 1]])
    for a, b in zip(chain(link_transforms(q)), chain(link_transforms(turned)), strict=True):
        np.testing.assert_allclose(rz @ a[:3, 3], b[:3, 3], atol=1e-12)


def _pose(p: dict[str, dict[str, float]]) -> np.ndarray:
    """A 4x4 from a foxglove Pose or FrameTransform (translation/position, rotation)."""
    t = p.get("translation") or p["position"]
    q = p.get("rotation") or p["orientation"]
    x, y, z, w = q["x"], q["y"], q["z"], q["w"]
    out = np.eye(4)
    out[:3, :3] = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                   [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                   [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
    out[:3, 3] = t["x"], t["y"], t["z"]
    return out


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short sim run with a noiseless, instant sim tracker (its mouth pose is the truth's)."""
    out = tmp_path_factory.mktemp("scene")
    rig = RigChoice(driver="sim", overrides=(
        "tracker.type='sim'", "tracker.position_noise_m=0", "tracker.yaw_noise_deg=0",
        "tracker.latency_s=0"))
    result = run_file(ROOT / "protocols/method1_case1.toml", ["run.timeout_s=1.2"], rig=rig,
                      out_dir=out)
    return result.path


def _read(path: Path) -> tuple[list[tuple[int, dict, str, str]], dict[int, dict[str, np.ndarray]],
                                list[tuple[int, np.ndarray]]]:
    """Scene messages (time, message, schema name, schema text), /tf by time and
    child frame, and the tracker's mouth poses, with the mcap reader and json only."""
    scenes, tf, mouths = [], defaultdict(dict), []
    with path.open("rb") as fh:
        for schema, channel, message in make_reader(fh).iter_messages(
                topics=["/scene/rig", "/tf", "/target/pose"]):
            if channel.topic == "/scene/rig":
                assert channel.message_encoding == "json" and schema.encoding == "jsonschema"
                scenes.append((message.log_time, json.loads(message.data), schema.name,
                               schema.data.decode()))
            elif channel.topic == "/tf":
                msg = json.loads(message.data)
                tf[message.log_time][msg["child_frame_id"]] = (msg["parent_frame_id"],
                                                                _pose(msg))
            else:  # CDR TargetPose: header, int64 time_ns, 16 f8 pose, 16 f8 mouth, ...
                mouth = np.frombuffer(message.data, "<f8", 16, 4 + 8 + 128).reshape(4, 4)
                valid = message.data[4 + 8 + 256]
                if valid:
                    mouths.append((message.log_time, mouth))
    return scenes, tf, mouths


def _in_base(frames: dict[str, tuple[str, np.ndarray]], frame: str) -> np.ndarray:
    pose = np.eye(4)
    while frame != "base":
        parent, t = frames[frame]
        pose = t @ pose
        frame = parent
    return pose


@pytest.mark.slow
def test_the_scene_in_a_recording_reads_with_its_schema_and_agrees_with_tf(
        recording: Path) -> None:
    scenes, tf, mouths = _read(recording)
    assert scenes, "no /scene/rig"
    t0, first, name, schema_text = scenes[0]
    assert name == "foxglove.SceneUpdate"
    schema = json.loads(schema_text)
    for _, msg, _, _ in scenes:
        jsonschema.validate(msg, schema)
    entities = {e["id"]: e for e in first["entities"]}
    assert {"bed", "base", "tool", "target", *(f"link{i}" for i in range(1, 8))} <= set(entities)
    assert all(e["frame_locked"] for e in entities.values())

    # every frame an entity names is on /tf from the scene's first time on
    frames_at_t0 = tf[t0]
    for e in entities.values():
        assert e["frame_id"] == "base" or e["frame_id"] in frames_at_t0, e["id"]

    # the tool cone's tip, through the forward-kinematics links, is the simulator's TCP
    cone = entities["tool"]["cylinders"][-1]
    assert cone["top_scale"] < cone["bottom_scale"]  # a cone narrowing to the tip
    tip_in_flange = _pose(cone["pose"]) @ np.array([0, 0, cone["size"]["z"] / 2, 1])
    checked = 0
    for frames in tf.values():
        if "link7" in frames and "tool" in frames:
            tip = _in_base(frames, "link7") @ tip_in_flange
            np.testing.assert_allclose(tip[:3], _in_base(frames, "tool")[:3, 3], atol=1e-9)
            checked += 1
    assert checked > 20

    # the target funnel's wide end, in the target's frame, is the funnel mouth the
    # (noiseless) tracker reports, and its axis is the mouth's x axis
    target = entities["target"]
    assert target["frame_id"] == "target"
    assert entities["target_tracked"]["frame_id"] == "target_tracked"  # the sim tracker's
    funnel = target["cylinders"][0]
    assert funnel["bottom_scale"] > funnel["top_scale"]
    fpose = _pose(funnel["pose"])
    mouth_in_target = fpose[:3, 3] - fpose[:3, 2] * funnel["size"]["z"] / 2
    assert mouths
    for log_time, mouth in mouths[:5]:
        target_in_base = _in_base(tf[max(t for t in tf if t <= log_time and "target" in tf[t])],
                                  "target")
        np.testing.assert_allclose(target_in_base[:3, :3] @ mouth_in_target
                                   + target_in_base[:3, 3], mouth[:3, 3], atol=2e-6)
        np.testing.assert_allclose(target_in_base[:3, :3] @ fpose[:3, 2], mouth[:3, 0],
                                   atol=1e-6)


def test_link_rows_are_the_link_transforms_bit_for_bit() -> None:
    """What ``/tf`` gets from the floats is what the 4x4 arrays hold (signed zeros too)."""
    from ffexp.scene3d.kinematics import link_rows, link_transforms

    rng = np.random.default_rng(0)
    for k in range(500):
        q = rng.uniform(-3.0, 3.0, 7)
        q[k % 7] = 0.0
        base = np.eye(4)
        base[:3, 3] = rng.normal(size=3)
        want = np.array([t.tolist() for t in link_transforms(q, base)])
        assert np.array(link_rows(q, base)).tobytes() == want.tobytes()
        assert np.array(link_rows(q)).tobytes() == np.array(link_transforms(q)).tobytes()



@pytest.mark.parametrize("arm_name", ["LWR4", "UR5E"])
def test_link_transforms_messages_are_encode_transform_of_link_rows(tmp_path: Path,
                                                                     arm_name: str) -> None:
    """The links' /tf messages written out are byte for byte the general encoding of the
    links' rows, on both branches of the quaternion (joints beyond 120 deg), at zero and
    at +-pi, with and without a base, and the general way for a DH arm."""
    import drivers.description as desc
    from ffexp.recording import Recorder
    from ffexp.scene3d.kinematics import link_frames, link_rows
    from ffexp.scene3d.linktf import LinkTransforms

    arm = getattr(desc, arm_name)
    rng = np.random.default_rng(5)
    frames = link_frames(arm)
    with Recorder(tmp_path / "tf.mcap") as rec:
        for base in (None, np.eye(4)):
            if base is not None:
                base[:3, 3] = (0.1, -0.2, 0.05)
            links = LinkTransforms(arm, base, frames, rec.encode_transform)
            for k in range(400):
                q = rng.uniform(-math.pi, math.pi, arm.joints)
                q[k % arm.joints] = (0.0, -0.0, math.pi, -math.pi, 2.5, -2.2)[k % 6]
                log_ns = 1_700_000_000_123_456_789 + 20_000_000 * k
                want = [rec.encode_transform(log_ns, parent, frame, rows) for parent, frame, rows
                        in zip(("base", *frames[:-1]), frames, link_rows(q, base, arm),
                               strict=True)]
                assert links.messages(log_ns, q) == want
            with pytest.raises(ValueError, match="not finite"):
                links.messages(0, np.full(arm.joints, np.nan))


def test_a_dh_arms_links_are_its_descriptions_joint_transforms() -> None:
    from drivers.description import UR5E
    from ffexp.scene3d.kinematics import link_rows

    rng = np.random.default_rng(1)
    for _ in range(20):
        q = rng.uniform(-3.0, 3.0, 6)
        want = UR5E.joint_transforms(q)
        got = link_transforms(q, arm=UR5E)
        assert [t.tobytes() for t in got] == [t.tobytes() for t in want]
        assert link_rows(q, arm=UR5E) == [t.tolist() for t in want]


def test_a_ur5e_run_draws_its_six_links_and_the_tool_tip_at_the_tcp(tmp_path: Path) -> None:
    result = run_file(ROOT / "protocols/method1_case1.toml", ["run.timeout_s=0.6"],
                      rig=RigChoice(ROOT / "rigs/ur5e-sim.toml"), out_dir=tmp_path)
    scenes, tf, _ = _read(result.path)
    entities = {e["id"]: e for e in scenes[0][1]["entities"]}
    links = {f"link{i}" for i in range(1, 7)}
    assert links <= set(entities) and "link7" not in entities
    assert all(entities[name]["cylinders"] for name in links)  # none of zero length
    cone = entities["tool"]["cylinders"][-1]
    assert entities["tool"]["frame_id"] == "link6"
    # the cone's narrow end (its pose holds the flange offset) is the TCP on /tf
    tip_in_link6 = _pose(cone["pose"]) @ np.array([0, 0, cone["size"]["z"] / 2, 1])
    checked = 0
    for frames in tf.values():
        if "link6" in frames and "tool" in frames:
            np.testing.assert_allclose((_in_base(frames, "link6") @ tip_in_link6)[:3],
                                       _in_base(frames, "tool")[:3, 3], atol=1e-9)
            checked += 1
    assert checked > 10


def test_the_scene_writer_batched_writes_what_it_writes_alone(tmp_path: Path) -> None:
    """Appended to the run log's batch of the cycle, the writer's messages are those it
    writes alone (topics, times, bytes, order); in cycles where nothing is due it adds
    nothing."""
    from collections.abc import Callable
    from types import SimpleNamespace

    from ffexp.recording import Recorder
    from ffexp.scene3d import SceneWriter

    scene = load_scene(ROOT / "data" / "scenes" / "paper.toml")
    q0 = np.array([0.1, 0.6, 0.0, -1.2, 0.0, 0.9, 0.2])
    seen: dict[str, list[tuple[str, int, bytes]]] = {"alone": [], "batched": []}

    def seen_by(got: list[tuple[str, int, bytes]]) -> Callable[[str, int, bytes], None]:
        return lambda topic, t, data: got.append((topic, t, data))

    added: list[int] = []
    for mode in ("alone", "batched"):
        with Recorder(tmp_path / f"{mode}.mcap") as rec:
            rec.taps.append(seen_by(seen[mode]))
            writer = SceneWriter(rec, scene, tf_period_s=0.02, scene_period_s=0.1)
            for k in range(100):
                q = q0 + 0.01 * k
                state = SimpleNamespace(tcp_pose_m=tcp_pose(scene, q), joint_pos_rad=q,
                                        truth=None)
                log_ns = 10**18 + k * 5_000_000
                if mode == "alone":
                    writer.cycle(log_ns, state, None)  # type: ignore[arg-type]
                else:
                    msgs: list[tuple[str, bytes]] = []
                    writer.cycle(log_ns, state, None, msgs)  # type: ignore[arg-type]
                    added.append(len(msgs))
                    if msgs:
                        rec.write_batch(log_ns, msgs)
    assert seen["alone"] == seen["batched"]
    assert added[:5] == [1 + 1 + 7, 0, 0, 0, 7]  # scene, its nominal target, the links
    assert sum(n == 0 for n in added) == 75


@pytest.mark.parametrize("scene_file", ["paper.toml", "paper-ur5e.toml"])
def test_each_links_cylinder_ends_at_the_next_joint_as_the_simulators_capsule(
        scene_file: str) -> None:
    from drivers.description import compute_layout
    from ffexp.scene3d.entities import LINK_RADIUS_M, scene_update

    scene = load_scene(ROOT / "data/scenes" / scene_file)
    arm = scene.arm.description
    tcp = tcp_pose(scene, np.array(scene.arm.q_init))
    layout = compute_layout(scene, tcp[:3, 3].copy(), tcp[:3, :3].copy())
    msg = scene_update(scene, layout, 0, "target", np.eye(4))
    entities = {e["id"]: e for e in msg["entities"]}
    last = arm.flange_m if arm.joint_rpy_rad is not None else (0.0, 0.0, 0.02)
    for i, end in enumerate((*arm.joint_origins_m[1:], last)):
        (cyl,) = entities[f"link{i + 1}"]["cylinders"]
        pose = _pose(cyl["pose"])
        half = cyl["size"]["z"] / 2
        np.testing.assert_allclose((pose @ [0, 0, -half, 1])[:3], 0.0, atol=1e-12)
        np.testing.assert_allclose((pose @ [0, 0, half, 1])[:3], end, atol=1e-12)
        assert cyl["size"]["x"] == pytest.approx(2 * LINK_RADIUS_M)
        np.testing.assert_allclose(np.linalg.det(pose[:3, :3]), 1.0, atol=1e-12)
