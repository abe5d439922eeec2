"""The run log's own messages joined from the arrays' bytes are the bytes of their
reference (every value packed in the topic's layout), which is the numpy record."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from drivers.base.types import (
    AppliedCommand,
    ApplyStatus,
    CartesianCommand,
    LinkHealth,
    RobotState,
)
from ffexp.recording.cycle import (
    command_message,
    command_packed,
    estimator_message,
    estimator_packed,
    state_message,
    state_packed,
    terms_message,
    terms_packed,
)
from ffexp.recording.topics import CDR_TOPICS, STATE_JOINTS


def _vec(rng: np.random.Generator, kind: int, n: int = 6) -> Any:
    """A 6-vector as the loop may give one: a float64 array (most often), a strided
    view, float32, integers, a list, a scalar."""
    base = rng.normal(size=n) * 10.0
    if kind == 0:
        return base
    if kind == 1:
        return np.repeat(base, 2)[::2]  # not contiguous
    if kind == 2:
        return base.astype(np.float32)
    if kind == 3:
        return np.round(base).astype(np.int64)
    if kind == 4:
        return base.tolist()
    return float(base[0])  # broadcast to six


def _pose(rng: np.random.Generator, kind: int) -> Any:
    m = rng.normal(size=(4, 4))
    if kind == 1:
        return np.asfortranarray(m)  # row-major bytes of a column-major array
    if kind == 2:
        return m.reshape(16)
    if kind == 3:
        return m.astype(np.float32)
    if kind == 4:  # a field of a numpy record: a float64 dtype not numpy's own object
        rec = np.zeros(2, dtype=[("pose", "<f8", (4, 4))])
        rec["pose"][1] = m
        return rec["pose"][1]
    return m


def _record(topic: str, values: dict[str, Any]) -> bytes:
    rec = CDR_TOPICS[topic].spec.new_record()
    for name, v in values.items():
        rec[name] = np.reshape(v, -1) if np.ndim(v) else v
    return rec.tobytes()


@pytest.mark.parametrize("seed", range(40))
def test_state_message_is_its_reference(seed: int) -> None:
    rng = np.random.default_rng(seed)
    kind = seed % 5
    n = int(rng.integers(3, 10))
    joints = rng.normal(size=n)
    if kind == 3:
        joints = joints.astype(np.float32)
    state = RobotState(
        time_ns=int(rng.integers(0, 2**62)), tcp_pose_m=_pose(rng, kind), joint_pos_rad=joints,
        link=LinkHealth(bool(seed % 2), bool(seed % 3), int(rng.integers(0, 2**40)),
                        float(rng.uniform(0.001, 0.01))),
        tcp_twist_mps_radps=None if seed % 4 == 0 else _vec(rng, seed % 4),
        ext_wrench_n_nm=None if seed % 3 == 0 else _vec(rng, seed % 6))
    data = state_message(state)
    assert data == state_packed(state)
    if kind in (0, 2, 4):  # the numpy record filled with the same values
        q = np.full(STATE_JOINTS, np.nan)
        q[:min(n, STATE_JOINTS)] = joints[:STATE_JOINTS]
        twist, ext = state.tcp_twist_mps_radps, state.ext_wrench_n_nm
        assert data == _record("/robot/state", {
            "time_ns": state.time_ns, "tcp_pose": state.tcp_pose_m, "joint_pos": q,
            "n_joints": n, "commanding": int(state.link.commanding),
            "healthy": int(state.link.healthy), "cycle": state.link.cycle,
            "cycle_s": state.link.cycle_s, "has_twist": int(twist is not None),
            "twist": np.broadcast_to(np.zeros(6) if twist is None else twist, (6,)),
            "has_ext_wrench": int(ext is not None),
            "ext_wrench": np.broadcast_to(np.zeros(6) if ext is None else ext, (6,))})


@pytest.mark.parametrize("seed", range(20))
def test_estimator_message_is_its_reference(seed: int) -> None:
    rng = np.random.default_rng(seed)
    arrays = [_vec(rng, (seed + k) % 4 if seed % 2 else 0) for k in range(4)]
    arrays = [np.asarray(a) for a in arrays]
    args = (*arrays, float(rng.normal()), int(rng.integers(0, 50)), bool(seed % 2))
    data = estimator_message(*args)
    assert data == estimator_packed(*args)
    if seed % 2 == 0:
        assert data == _record("/estimator/state", dict(zip(
            ("wrench", "wrench_std", "bias", "twist_tcf", "f_z", "n_samples", "in_contact"),
            args, strict=True)))


@pytest.mark.parametrize("seed", range(40))
def test_terms_message_is_its_reference(seed: int) -> None:
    rng = np.random.default_rng(seed)
    if seed % 4 == 0:
        terms = None
    else:
        terms = SimpleNamespace(**{name: None if rng.uniform() < 0.2 else _vec(rng, int(
            rng.integers(0, 6))) for name in ("p", "i", "ri", "ff", "impedance")})
        if seed % 3:
            terms.saturated = bool(seed % 2)
        if seed % 5 == 0:
            del terms.impedance  # a method without that term
    approach = None if seed % 2 else _vec(rng, 0 if seed % 3 else 1)
    total = _vec(rng, 0 if seed % 7 else 2)
    f_ref = _vec(rng, int(rng.integers(0, 6)))
    setpoint = _pose(rng, seed % 5)
    phase = int(rng.integers(0, 5))
    data = terms_message(terms, approach, total, f_ref, setpoint, phase)
    assert data == terms_packed(terms, approach, total, f_ref, setpoint, phase)
    assert len(data) == CDR_TOPICS["/control/terms"].spec.layout.size


def test_terms_of_a_plain_cycle_are_the_numpy_record() -> None:
    rng = np.random.default_rng(7)
    p, i, ri, ff, total, f_ref = (rng.normal(size=6) for _ in range(6))
    setpoint = rng.normal(size=(4, 4))
    terms = SimpleNamespace(p=p, i=i, ri=ri, ff=ff, impedance=None, saturated=True)
    approach = rng.normal(size=6)
    data = terms_message(terms, approach, total, f_ref, setpoint, 3)
    assert data == _record("/control/terms", {
        "p": p, "i": i, "ri": ri, "ff": ff, "impedance": approach, "total": total,
        "f_ref": f_ref, "setpoint": setpoint, "phase": 3, "saturated": 1})


@pytest.mark.parametrize("seed", range(30))
def test_command_message_is_its_reference(seed: int) -> None:
    rng = np.random.default_rng(seed)

    def command(kind: int) -> CartesianCommand:
        return CartesianCommand(_pose(rng, kind), _vec(rng, kind), _vec(rng, 0),
                                _vec(rng, (kind + 1) % 6))

    intent = None if seed % 3 == 0 else command(seed % 5)
    applied = AppliedCommand(command((seed + 2) % 5), ApplyStatus(seed % 16))
    data = command_message(intent, applied)
    assert data == command_packed(intent, applied)
    assert len(data) == CDR_TOPICS["/control/command"].spec.layout.size


def test_a_value_of_another_size_is_refused_as_the_reference_refuses_it() -> None:
    state = RobotState(ext_wrench_n_nm=np.zeros(5))
    with pytest.raises(ValueError):
        state_packed(state)
    with pytest.raises(ValueError):
        state_message(state)
    with pytest.raises(Exception):  # noqa: B017  # struct.error: 15 values for 16
        terms_message(None, None, np.zeros(6), np.zeros(6), np.zeros(15), 0)


def test_the_loops_float64_arrays_take_the_joined_form(monkeypatch: pytest.MonkeyPatch) -> None:
    import ffexp.recording.cycle as cycle

    def refused(*_a: object) -> bytes:
        raise AssertionError("the reference was used")

    for name in ("state_packed", "estimator_packed", "terms_packed", "command_packed"):
        monkeypatch.setattr(cycle, name, refused)
    rng = np.random.default_rng(3)
    state = RobotState(tcp_pose_m=_pose(rng, 4), joint_pos_rad=rng.normal(size=6),
                       ext_wrench_n_nm=rng.normal(size=6))
    assert len(cycle.state_message(state)) == CDR_TOPICS["/robot/state"].spec.layout.size
    v = rng.normal(size=6)
    cycle.estimator_message(v, v, v, v, 1.0, 3, True)
    cycle.terms_message(SimpleNamespace(p=v, i=v, ri=None, ff=v), None, v, v, _pose(rng, 1), 2)
    cycle.command_message(CartesianCommand(), AppliedCommand(CartesianCommand()))


def _other_f64(v: np.ndarray, big_endian: bool = False) -> np.ndarray:
    """``v`` with a float64 dtype that is not numpy's own object (one with metadata)
    or, ``big_endian``, in the other byte order: the same numbers."""
    if big_endian:
        return v.astype(">f8")
    out: np.ndarray = v.view(np.dtype(np.float64, metadata={"unit": "m"}))
    assert out.dtype == np.float64 and out.dtype is not np.dtype(np.float64)
    return out


@pytest.mark.parametrize("big_endian", [False, True])
def test_float64_vectors_of_another_dtype_object_give_the_reference(big_endian: bool) -> None:
    """The joined form takes numpy's own float64 dtype at once; a float64 of another
    dtype object, or another byte order, still gives the reference's bytes."""
    rng = np.random.default_rng(11)
    vec = [_other_f64(rng.normal(size=6), big_endian) for _ in range(6)]
    state = RobotState(time_ns=5, tcp_pose_m=_other_f64(rng.normal(size=(4, 4)), big_endian),
                       joint_pos_rad=_other_f64(rng.normal(size=7), big_endian),
                       link=LinkHealth(True, True, 3, 0.004),
                       tcp_twist_mps_radps=vec[0], ext_wrench_n_nm=vec[1])
    assert state_message(state) == state_packed(state)
    plain = RobotState(time_ns=5, tcp_pose_m=state.tcp_pose_m.astype(np.float64),
                       joint_pos_rad=state.joint_pos_rad.astype(np.float64),
                       link=state.link, tcp_twist_mps_radps=vec[0].astype(np.float64),
                       ext_wrench_n_nm=vec[1].astype(np.float64))
    assert state_message(state) == state_message(plain)
    args = (*vec[2:], 0.5, 4, True)
    assert estimator_message(*args) == estimator_packed(*args)
    assert estimator_message(*args) == estimator_message(
        *[v.astype(np.float64) for v in vec[2:]], 0.5, 4, True)
    total, setpoint = vec[0], _other_f64(rng.normal(size=(4, 4)), big_endian)
    terms = SimpleNamespace(p=vec[1], i=vec[2], ri=vec[3], ff=vec[4], impedance=vec[5],
                            saturated=True)
    for approach in (None, vec[5].astype(np.float64)):
        got = terms_message(terms, approach, total, vec[3], setpoint, 3)
        assert got == terms_packed(terms, approach, total, vec[3], setpoint, 3)
