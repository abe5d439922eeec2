"""The recorder's fast encodings write the very bytes of the numpy records they replace."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from ffexp.recording import Recorder, load
from ffexp.recording.encode import FieldsEncoder
from ffexp.recording.schema import CDR_HEADER, MessageSpec
from ffexp.recording.topics import CDR_TOPICS


def _values(spec: MessageSpec, rng: np.random.Generator) -> dict[str, object]:
    """Random plain values of every field (arrays of the field's type, Python scalars)."""
    out: dict[str, object] = {}
    for f in spec.fields:
        dtype = spec.dtype.fields[f.name][0].base  # type: ignore[index]
        if dtype.kind == "f":
            arr = (rng.normal(size=f.count) * 1e3).astype(dtype)
        else:
            arr = rng.integers(0, np.iinfo(dtype).max, size=f.count, endpoint=True).astype(dtype)
        out[f.name] = arr if f.count > 1 else arr[0].item()
    return out


def _record(spec: MessageSpec, values: dict[str, object]) -> bytes:
    rec = spec.new_record()
    for f in spec.fields:
        v = values[f.name]
        rec[f.name] = np.reshape(v, -1) if f.count > 1 else v  # type: ignore[call-overload]
    return rec.tobytes()


@pytest.mark.parametrize("topic", sorted(CDR_TOPICS))
def test_layout_and_encoder_bytes_equal_the_numpy_record(topic: str) -> None:
    spec = CDR_TOPICS[topic].spec
    rng = np.random.default_rng(7)
    for _ in range(5):
        values = _values(spec, rng)
        want = _record(spec, values)
        flat: list[object] = [CDR_HEADER]
        for f in spec.fields:
            v = values[f.name]
            flat += v.tolist() if isinstance(v, np.ndarray) else [v]
        assert spec.layout.pack(*flat) == want
        assert FieldsEncoder(spec).encode(SimpleNamespace(**values)) == want


def test_encoder_declines_what_numpy_would_convert_and_the_recorder_falls_back(
        tmp_path: Path) -> None:
    spec = CDR_TOPICS["/sim/truth"].spec
    values = _values(spec, np.random.default_rng(3))
    enc = FieldsEncoder(spec)
    odd: list[dict[str, object]] = [
        {"in_contact": 1.0},  # a float into a uint8 field
        {"in_contact": np.bool_(True)},  # a numpy bool
        {"contact_wrench": np.reshape(values["contact_wrench"], (2, 3))},  # type: ignore[call-overload]
        {"tcp_twist": np.arange(6, dtype=np.float32)},  # another type: numpy converts
        {"tcp_twist": [0.0, 1.0, 2.0, 3.0, 4.0, 5.0]},  # a list
    ]
    path = tmp_path / "a.mcap"
    wants = []
    with Recorder(path) as rec:
        for k, change in enumerate(odd):
            source = SimpleNamespace(**{**values, **change})
            if "contact_wrench" not in change:
                assert enc.encode(source) is None
            wants.append(_record(spec, {**values, **change}))
            rec.write_fields("/sim/truth", 10**9 + k, source)
    data = load(path).topic("/sim/truth")
    want = np.frombuffer(b"".join(wants), dtype=spec.dtype)
    for f in spec.fields:
        np.testing.assert_array_equal(data[f.name].reshape(want[f.name].shape), want[f.name])


def _old_pose_to_transform(pose: np.ndarray) -> tuple[float, ...]:
    """The former array form of the quaternion (Shepperd's method on numpy scalars)."""
    import math

    r = pose[:3, :3]
    tr = float(r[0, 0] + r[1, 1] + r[2, 2])
    if tr > 0.0:
        s = 2.0 * math.sqrt(tr + 1.0)
        q = [(r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, 0.25 * s]
    else:
        i = int(np.argmax(np.diag(r)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(max(1.0 + r[i, i] - r[j, j] - r[k, k], 1e-300))
        q = [0.0, 0.0, 0.0, (r[k, j] - r[j, k]) / s]
        q[i] = 0.25 * s
        q[j] = (r[j, i] + r[i, j]) / s
        q[k] = (r[k, i] + r[i, k]) / s
    return (float(pose[0, 3]), float(pose[1, 3]), float(pose[2, 3]), *map(float, q))


def test_pose_floats_equal_the_array_form_bit_for_bit() -> None:
    from scipy.spatial.transform import Rotation

    from ffexp.recording.recorder import pose_floats

    rng = np.random.default_rng(11)
    flips = [np.diag(d) for d in ((1, -1, -1), (-1, 1, -1), (-1, -1, 1))]
    for k in range(3000):
        pose = np.eye(4)
        rot = Rotation.random(random_state=k).as_matrix()
        pose[:3, :3] = flips[k % 3] @ rot if k % 4 == 0 else rot  # trace <= 0 too
        if k % 5 == 0:
            pose[:3, :3] = flips[k % 3]  # ties on the diagonal
        pose[:3, 3] = rng.normal(size=3)
        want = _old_pose_to_transform(pose)
        assert np.array(pose_floats(pose)).tobytes() == np.array(want).tobytes(), k


@pytest.mark.parametrize("topic", sorted(CDR_TOPICS))
def test_compiled_encoder_equals_the_segment_walk(topic: str) -> None:
    """The generated straight-line encoder gives what walking the segments gives, for
    plain values and for each value numpy would convert (both decline those)."""
    spec = CDR_TOPICS[topic].spec
    enc = FieldsEncoder(spec)
    rng = np.random.default_rng(11)
    values = _values(spec, rng)
    assert enc.encode(SimpleNamespace(**values)) == enc.encode_segments(
        SimpleNamespace(**values)) is not None
    for f in spec.fields:
        odd: object = 1.5 if f.count == 1 else np.zeros(f.count, dtype=np.float32)
        source = SimpleNamespace(**{**values, f.name: odd})
        assert enc.encode(source) == enc.encode_segments(source)


@pytest.mark.parametrize("topic", sorted(CDR_TOPICS))
def test_the_recorders_encoder_equals_encode_fields(topic: str, tmp_path: Path) -> None:
    """``Recorder.encoder(topic)`` (the compiled encoder with the numpy record compiled
    in as its fallback) gives the bytes of ``encode_fields`` for plain values and for
    each value numpy would convert; an error of the fallback reaches the caller."""
    spec = CDR_TOPICS[topic].spec
    rng = np.random.default_rng(13)
    with Recorder(tmp_path / "a.mcap") as rec:
        encode = rec.encoder(topic)
        assert rec.encoder(topic) is encode  # one function a topic
        values = _values(spec, rng)
        assert encode(SimpleNamespace(**values)) == rec.encode_fields(
            topic, SimpleNamespace(**values)) == _record(spec, values)
        for f in spec.fields:
            for odd in ((1.0, True) if f.count == 1 else
                        (np.arange(f.count, dtype=np.float32), list(range(f.count)))):
                source = SimpleNamespace(**{**values, f.name: odd})
                assert encode(source) == rec.encode_fields(topic, source)
        bad = SimpleNamespace(**{**values, spec.fields[0].name: "not a number"})
        with pytest.raises((TypeError, ValueError)):
            encode(bad)


def test_two_recorders_run_one_compiled_code_each_with_its_own_fallback(
        tmp_path: Path) -> None:
    """The encoders' code is compiled once a process; each recorder's encoder still falls
    back to its own numpy record (the bytes of each recorder's values, interleaved)."""
    spec = CDR_TOPICS["/sim/truth"].spec
    rng = np.random.default_rng(21)
    with Recorder(tmp_path / "a.mcap") as a, Recorder(tmp_path / "b.mcap") as b:
        ea, eb = a.encoder("/sim/truth"), b.encoder("/sim/truth")
        assert ea is not eb and ea.__code__ is eb.__code__
        for _ in range(5):
            va, vb = _values(spec, rng), _values(spec, rng)
            va["in_contact"], vb["in_contact"] = 1.0, 0.0  # floats: each falls back
            got_a = ea(SimpleNamespace(**va))
            got_b = eb(SimpleNamespace(**vb))
            assert got_a == _record(spec, va) and got_b == _record(spec, vb)


@pytest.mark.parametrize("topic", sorted(t for t, c in CDR_TOPICS.items()
                                         if any(f.count > 1 for f in c.spec.fields)))
def test_arrays_of_an_equal_dtype_of_another_object_encode_as_the_record(topic: str) -> None:
    """The encoder takes an array field's own numpy dtype by identity first; an equal
    dtype that is another object (one with metadata) is taken too, and another byte
    order is declined: each gives the numpy record's bytes (through the fallback)."""
    spec = CDR_TOPICS[topic].spec
    values = _values(spec, np.random.default_rng(5))
    want = _record(spec, values)
    arrays = [k for k, v in values.items() if isinstance(v, np.ndarray)]
    tagged = {k: v.view(np.dtype(v.dtype, metadata={"unit": "x"})) if k in arrays else v
              for k, v in values.items()}
    assert all(tagged[k].dtype is not values[k].dtype for k in arrays)  # type: ignore[union-attr]
    assert FieldsEncoder(spec).encode(SimpleNamespace(**tagged)) == want
    swapped = {k: v.astype(v.dtype.newbyteorder()) if k in arrays and v.dtype.itemsize > 1
               else v for k, v in values.items()}
    enc = FieldsEncoder(spec).with_fallback(lambda s: _record(spec, vars(s)))
    assert enc(SimpleNamespace(**swapped)) == want
