"""The run log's own per-cycle messages as bytes: ``/robot/state``, ``/estimator/state``,
``/control/terms`` and ``/control/command``.

Each has a reference form (:func:`state_packed`, ...: every value flattened into one
``struct`` layout, the topic's :attr:`MessageSpec.layout
<ffexp.recording.schema.MessageSpec.layout>`) and a fast form (:func:`state_message`,
...) that joins the arrays' own bytes (``tobytes``, row-major) with the scalars packed
between them, padding included. The fast form takes only float64 arrays of the field's
shape (a 4x4 pose, a 6-vector; what the loop gives every cycle) and hands anything else
to the reference, so the bytes are always the reference's: a float64's bytes are the
double ``struct`` packs from its Python float (``tests/test_recording_cycle.py``).
"""

from __future__ import annotations

from struct import Struct
from typing import Any

import numpy as np

from drivers.base.types import AppliedCommand, CartesianCommand, RobotState
from ffexp.recording.schema import CDR_HEADER
from ffexp.recording.topics import CDR_TOPICS, STATE_JOINTS

__all__ = ["TERMS", "command_message", "command_packed", "estimator_message",
           "estimator_packed", "floats6", "state_message", "state_packed", "terms_message",
           "terms_packed"]

TERMS = ("p", "i", "ri", "ff", "impedance")
_F8 = np.dtype(np.float64)
_ND = np.ndarray
_V6 = (6,)
_NAN = float("nan")
_ZEROS6 = [0.0] * 6
_ZEROS_5X6 = [0.0] * 30
_ZEROS_34 = [0.0] * 34  # pose, stiffness, damping and wrench of no intent
_Z48 = bytes(48)  # six zeros
_Z240 = bytes(240)  # five terms of zeros
_Z272 = bytes(272)  # an intent's pose, stiffness, damping and wrench of zeros

_STATE = CDR_TOPICS["/robot/state"].spec.layout
_ESTIMATOR = CDR_TOPICS["/estimator/state"].spec.layout
_TERMS_LAYOUT = CDR_TOPICS["/control/terms"].spec.layout
_COMMAND = CDR_TOPICS["/control/command"].spec.layout
# the scalars between the arrays, with the layouts' padding (checked at import below)
_STATE_HEAD = Struct("<4sq")  # header, time_ns; then pose 16d and joints 7d
_STATE_LINK = Struct("<BBB5xqdB7x")  # n, commanding, healthy, cycle, cycle_s, has_twist
_STATE_EXT = Struct("<B7x")  # has_ext_wrench; then ext_wrench 6d
_EST_TAIL = Struct("<dIB")  # f_z, n_samples, in_contact
_TERMS_TAIL = Struct("<iB")  # phase, saturated
_COMMAND_TAIL = Struct("<IB")  # status, given
_PACK6 = Struct("<6d").pack
_NAN_PAD = [Struct(f"<{k}d").pack(*[_NAN] * k) for k in range(STATE_JOINTS + 1)]
assert (_STATE_HEAD.size + 23 * 8 + _STATE_LINK.size + 48 + _STATE_EXT.size + 48
        == _STATE.size)
assert 4 + 24 * 8 + _EST_TAIL.size == _ESTIMATOR.size
assert 4 + 58 * 8 + _TERMS_TAIL.size == _TERMS_LAYOUT.size
assert 4 + 68 * 8 + _COMMAND_TAIL.size == _COMMAND.size


def floats6(value: Any) -> list[float]:
    """A 6-vector's elements as floats (an array, or anything numpy makes one of:
    the recording stays what filling a numpy record with it gave)."""
    if type(value) is np.ndarray and value.shape == (6,):
        out: list[float] = value.tolist()
        return out
    return list(np.broadcast_to(np.asarray(value, dtype=np.float64), (6,)).tolist())


def _b6(value: Any) -> bytes:
    """A 6-vector's message bytes (:func:`floats6` packed)."""
    if type(value) is _ND and value.shape == _V6 and (value.dtype is _F8
                                                       or value.dtype == _F8):
        return value.tobytes()
    return _PACK6(*floats6(value))


# -- /robot/state -----------------------------------------------------------------------
def state_packed(state: RobotState) -> bytes:
    """``/robot/state``'s message (the reference)."""
    joints = state.joint_pos_rad
    n = len(joints)
    q = joints[:STATE_JOINTS].tolist()
    if n < STATE_JOINTS:
        q += [_NAN] * (STATE_JOINTS - n)
    link = state.link
    twist, ext = state.tcp_twist_mps_radps, state.ext_wrench_n_nm
    return _STATE.pack(
        CDR_HEADER, state.time_ns, *state.tcp_pose_m.ravel().tolist(), *q, n,
        int(link.commanding), int(link.healthy), link.cycle, link.cycle_s,
        int(twist is not None), *(_ZEROS6 if twist is None else floats6(twist)),
        int(ext is not None), *(_ZEROS6 if ext is None else floats6(ext)))


def state_message(state: RobotState) -> bytes:
    """:func:`state_packed`, the arrays' bytes joined."""
    pose, joints = state.tcp_pose_m, state.joint_pos_rad
    if (type(pose) is not _ND or type(joints) is not _ND
            or (pose.dtype is not _F8 and pose.dtype != _F8) or pose.size != 16
            or (joints.dtype is not _F8 and joints.dtype != _F8) or joints.ndim != 1):
        return state_packed(state)
    n = len(joints)
    q = joints.tobytes() if n == STATE_JOINTS else (
        joints[:STATE_JOINTS].tobytes() if n > STATE_JOINTS
        else joints.tobytes() + _NAN_PAD[STATE_JOINTS - n])
    link = state.link
    twist, ext = state.tcp_twist_mps_radps, state.ext_wrench_n_nm
    tw = _Z48 if twist is None else _b6(twist)
    ex = _Z48 if ext is None else _b6(ext)
    return b"".join((
        _STATE_HEAD.pack(CDR_HEADER, state.time_ns), pose.tobytes(), q,
        _STATE_LINK.pack(n, int(link.commanding), int(link.healthy), link.cycle, link.cycle_s,
                         twist is not None),
        tw, _STATE_EXT.pack(ext is not None), ex))


# -- /estimator/state -------------------------------------------------------------------
def estimator_packed(wrench: Any, std: Any, bias: Any, twist: Any, f_z: float, n: int,
                     in_contact: bool) -> bytes:
    """``/estimator/state``'s message (the reference)."""
    return _ESTIMATOR.pack(CDR_HEADER, *wrench.tolist(), *std.tolist(), *bias.tolist(),
                           *twist.tolist(), f_z, n, int(in_contact))


def estimator_message(wrench: Any, std: Any, bias: Any, twist: Any, f_z: float, n: int,
                      in_contact: bool) -> bytes:
    """:func:`estimator_packed`, the arrays' bytes joined."""
    if (type(wrench) is _ND and type(std) is _ND and type(bias) is _ND and type(twist) is _ND
            and wrench.dtype is _F8 and std.dtype is _F8 and bias.dtype is _F8
            and twist.dtype is _F8 and wrench.shape == _V6 and std.shape == _V6
            and bias.shape == _V6 and twist.shape == _V6):
        return b"".join((CDR_HEADER, wrench.tobytes(), std.tobytes(), bias.tobytes(),
                         twist.tobytes(), _EST_TAIL.pack(f_z, n, int(in_contact))))
    return estimator_packed(wrench, std, bias, twist, f_z, n, in_contact)


# -- /control/terms ---------------------------------------------------------------------
def terms_packed(terms: object | None, approach_wrench: Any, total: Any, f_ref: Any,
                 setpoint: Any, phase: int) -> bytes:
    """``/control/terms``'s message (the reference): the controller's ``terms`` (``None``
    outside ALIGN; a term it lacks is zeros), the approach law's wrench in place of the
    impedance term when it acted."""
    values: list[object] = [CDR_HEADER]
    if terms is None:
        values += _ZEROS_5X6
    else:
        for name in TERMS:
            value = getattr(terms, name, None)
            values += _ZEROS6 if value is None else floats6(value)
    if approach_wrench is not None:
        values[25:31] = approach_wrench.tolist()
    values += total.tolist()
    values += floats6(f_ref)
    values += setpoint.ravel().tolist()
    values.append(phase)
    values.append(int(bool(getattr(terms, "saturated", False))))
    return _TERMS_LAYOUT.pack(*values)


def terms_message(terms: object | None, approach_wrench: Any, total: Any, f_ref: Any,
                  setpoint: Any, phase: int) -> bytes:
    """:func:`terms_packed`, the arrays' bytes joined."""
    if (type(total) is not _ND or type(setpoint) is not _ND
            or (total.dtype is not _F8 and total.dtype != _F8) or total.shape != _V6
            or (setpoint.dtype is not _F8 and setpoint.dtype != _F8) or setpoint.size != 16
            or (approach_wrench is not None and (
                type(approach_wrench) is not _ND or approach_wrench.dtype != _F8
                or approach_wrench.shape != _V6))):
        return terms_packed(terms, approach_wrench, total, f_ref, setpoint, phase)
    if terms is None:
        head = _Z240 if approach_wrench is None else _Z240[:192] + approach_wrench.tobytes()
        saturated = False
    else:
        p, i, ri, ff = (getattr(terms, "p", None), getattr(terms, "i", None),
                        getattr(terms, "ri", None), getattr(terms, "ff", None))
        head = b"".join((
            _Z48 if p is None else _b6(p), _Z48 if i is None else _b6(i),
            _Z48 if ri is None else _b6(ri), _Z48 if ff is None else _b6(ff)))
        if approach_wrench is not None:
            head += approach_wrench.tobytes()
        else:
            imp = getattr(terms, "impedance", None)
            head += _Z48 if imp is None else _b6(imp)
        saturated = bool(getattr(terms, "saturated", False))
    return b"".join((CDR_HEADER, head, total.tobytes(), _b6(f_ref), setpoint.tobytes(),
                     _TERMS_TAIL.pack(phase, saturated)))


# -- /control/command -------------------------------------------------------------------
def command_packed(intent: CartesianCommand | None, applied: AppliedCommand) -> bytes:
    """``/control/command``'s message (the reference)."""
    a = applied.command
    values: list[object] = [CDR_HEADER]
    if intent is not None:
        values += intent.pose_m.ravel().tolist()
        values += floats6(intent.stiffness_npm_nmprad)
        values += floats6(intent.damping_ratio)
        values += floats6(intent.wrench_n_nm)
    else:  # the robot keeps its own set-point: nothing was asked
        values += _ZEROS_34
    values += a.pose_m.ravel().tolist()
    values += floats6(a.stiffness_npm_nmprad)
    values += floats6(a.damping_ratio)
    values += floats6(a.wrench_n_nm)
    values.append(int(applied.status))
    values.append(int(intent is not None))
    return _COMMAND.pack(*values)


def command_message(intent: CartesianCommand | None, applied: AppliedCommand) -> bytes:
    """:func:`command_packed`, the arrays' bytes joined."""
    a = applied.command
    pose = a.pose_m
    if type(pose) is not _ND or pose.dtype != _F8 or pose.size != 16:
        return command_packed(intent, applied)
    if intent is None:
        asked = _Z272
    else:
        ipose = intent.pose_m
        if type(ipose) is not _ND or ipose.dtype != _F8 or ipose.size != 16:
            return command_packed(intent, applied)
        asked = b"".join((ipose.tobytes(), _b6(intent.stiffness_npm_nmprad),
                          _b6(intent.damping_ratio), _b6(intent.wrench_n_nm)))
    return b"".join((CDR_HEADER, asked, pose.tobytes(), _b6(a.stiffness_npm_nmprad),
                     _b6(a.damping_ratio), _b6(a.wrench_n_nm),
                     _COMMAND_TAIL.pack(int(applied.status), intent is not None)))
