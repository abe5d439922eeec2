"""The RTDE register map of ffexp's URScript program and the command -> registers rule (pure).

``drivers/ur/ffexp_control.script`` reads these input registers every cycle
and writes these output registers (the map is also in docs/ur.md). All of
them are in the "upper range" (24..47), which fieldbus adapters leave free.

The rule (:func:`fill_command`): an axis of the tool frame whose commanded
stiffness is at most ``force_axis_stiffness_npm_nmprad`` is *compliant* (its
bit in the selection vector set, force mode applies the command's wrench on
it, its speed capped by ``compliant_speed_limits_mps_radps``); every other
axis follows the commanded pose (the servo), within
``deviation_limits_m_rad``. A command with no compliant axis is a pure pose
servo; no command (``None``) holds the arm where it is.
"""

from __future__ import annotations

import math
from enum import IntEnum
from functools import lru_cache
from typing import Final

import numpy as np
from numpy.typing import NDArray

from drivers.base.types import CartesianCommand

BASE: Final = 24


def _in_int(i: int) -> str:
    return f"input_int_register_{BASE + i}"


def _in_double(i: int) -> str:
    return f"input_double_register_{BASE + i}"


SEQ: Final = _in_int(0)
MODE: Final = _in_int(1)
SELECTION: Final = _in_int(2)
POSE: Final = tuple(_in_double(i) for i in range(0, 6))
WRENCH: Final = tuple(_in_double(i) for i in range(6, 12))
LIMITS: Final = tuple(_in_double(i) for i in range(12, 18))
DAMPING: Final = _in_double(18)
GAIN_SCALING: Final = _in_double(19)
LOOKAHEAD: Final = _in_double(20)
SERVO_GAIN: Final = _in_double(21)
#: Every input register the program reads, in recipe order.
INPUT_NAMES: Final = (SEQ, MODE, SELECTION, *POSE, *WRENCH, *LIMITS, DAMPING, GAIN_SCALING,
                      LOOKAHEAD, SERVO_GAIN)

APPLIED_SEQ: Final = f"output_int_register_{BASE}"
SCRIPT_STATE: Final = f"output_int_register_{BASE + 1}"


class Mode(IntEnum):
    """What the program does with a command."""

    HOLD = 0
    SERVO = 1
    FORCE = 2
    END = 3


class ScriptState(IntEnum):
    """What the program reports (0 before it first runs)."""

    NOT_RUNNING = 0
    RUNNING = 1
    ENDED = 2
    HELD_STALE = 3


def pose_vector(pose_m: NDArray[np.float64]) -> NDArray[np.float64]:
    """A 4x4 pose as UR's 6-vector ``[x, y, z, rx, ry, rz]`` (rotation vector, angle in
    [0, pi]) [m, rad].

    The rotation vector via the unit quaternion (Shepperd's branches), in plain floats:
    scipy's ``Rotation.from_matrix`` costs about 0.15 ms a call here, twice per cycle at
    500 Hz (benchmarks/bench_ur_sim.py); tests/test_ur_sim.py checks this against it.
    """
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = pose_m[:3, :3].tolist()
    tr = m00 + m11 + m22
    if tr > 0.0:
        s = math.sqrt(tr + 1.0) * 2.0
        w, x, y, z = 0.25 * s, (m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s
    elif m00 > m11 and m00 > m22:
        s = math.sqrt(1.0 + m00 - m11 - m22) * 2.0
        w, x, y, z = (m21 - m12) / s, 0.25 * s, (m01 + m10) / s, (m02 + m20) / s
    elif m11 > m22:
        s = math.sqrt(1.0 + m11 - m00 - m22) * 2.0
        w, x, y, z = (m02 - m20) / s, (m01 + m10) / s, 0.25 * s, (m12 + m21) / s
    else:
        s = math.sqrt(1.0 + m22 - m00 - m11) * 2.0
        w, x, y, z = (m10 - m01) / s, (m02 + m20) / s, (m12 + m21) / s, 0.25 * s
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    n = math.sqrt(x * x + y * y + z * z)
    k = 2.0 * math.atan2(n, w) / n if n > 1e-12 else 2.0 / w
    out = np.empty(6)
    out[:3] = pose_m[:3, 3]
    out[3:] = (k * x, k * y, k * z)
    return out


def pose_matrix(vector: NDArray[np.float64], out: NDArray[np.float64] | None = None
                ) -> NDArray[np.float64]:
    """UR's pose 6-vector as a 4x4 pose (into ``out`` when given): Rodrigues' formula in
    plain floats (scipy's ``Rotation`` is slow per call, as for :func:`pose_vector`)."""
    x, y, z, rx, ry, rz = (float(v) for v in vector[:6])
    angle = math.sqrt(rx * rx + ry * ry + rz * rz)
    if angle < 1e-12:
        rows = [[1.0, -rz, ry, x], [rz, 1.0, -rx, y], [-ry, rx, 1.0, z], [0.0, 0.0, 0.0, 1.0]]
    else:
        kx, ky, kz = rx / angle, ry / angle, rz / angle
        c, s = math.cos(angle), math.sin(angle)
        v = 1.0 - c
        rows = [[c + kx * kx * v, kx * ky * v - kz * s, kx * kz * v + ky * s, x],
                [ky * kx * v + kz * s, c + ky * ky * v, ky * kz * v - kx * s, y],
                [kz * kx * v - ky * s, kz * ky * v + kx * s, c + kz * kz * v, z],
                [0.0, 0.0, 0.0, 1.0]]
    if out is None:  # (one array from the rows: cheaper than filling an identity)
        return np.array(rows)
    out[...] = rows
    return out


def selection_bits(compliant: NDArray[np.bool_]) -> int:
    """The selection vector as the program's bit mask (bit i = axis i)."""
    return int(sum(1 << i for i in range(6) if compliant[i]))


def selection_axes(bits: int) -> NDArray[np.bool_]:
    """The program's bit mask as the selection vector (:func:`selection_bits`' inverse;
    the bits above the sixth axis are not read): one read-only array per mask."""
    return _COMPLIANT[bits & 63]


def fill_command(record: np.ndarray, seq: int, cmd: CartesianCommand | None,
                 hold_pose_m: NDArray[np.float64], *, stiffness_max: float,
                 speed_limits: NDArray[np.float64], deviation_limits: NDArray[np.float64],
                 damping: float, gain_scaling: float, lookahead_s: float,
                 servo_gain: float) -> Mode:
    """Write one cycle's command into ``record`` (an input recipe record over
    :data:`INPUT_NAMES`) and return the mode. ``None`` holds at ``hold_pose_m``."""
    if cmd is None:
        target = pose_vector(hold_pose_m)
        wrench, (mode, bits, limits) = _ZERO6, _axes(None, stiffness_max,
                                                     speed_limits.tobytes(),
                                                     deviation_limits.tobytes())
    else:
        target = pose_vector(cmd.pose_m)
        k = np.asarray(cmd.stiffness_npm_nmprad, dtype=np.float64)
        mode, bits, limits = _axes(k.tobytes(), stiffness_max, speed_limits.tobytes(),
                                   deviation_limits.tobytes())
        wrench = np.where(selection_axes(bits), cmd.wrench_n_nm, 0.0).tolist()
    if record.dtype.names == INPUT_NAMES:  # every field at once, in recipe order
        record[()] = (seq & 0x7FFFFFFF, int(mode), bits, *target.tolist(), *wrench, *limits,
                      damping, gain_scaling, lookahead_s, servo_gain)
        return mode
    record[SEQ] = seq & 0x7FFFFFFF
    record[DAMPING] = damping
    record[GAIN_SCALING] = gain_scaling
    record[LOOKAHEAD] = lookahead_s
    record[SERVO_GAIN] = servo_gain
    record[MODE] = int(mode)
    record[SELECTION] = bits
    for names, values in ((POSE, target.tolist()), (WRENCH, wrench), (LIMITS, limits)):
        for name, value in zip(names, values, strict=True):
            record[name] = value
    return mode


_ZERO6: Final = [0.0] * 6


def _mask_axes(bits: int) -> NDArray[np.bool_]:
    axes = np.array([bool(bits >> i & 1) for i in range(6)])
    axes.flags.writeable = False  # (shared by every command with this mask)
    return axes


#: The compliant axes of each selection mask (bit i = axis i).
_COMPLIANT: Final = tuple(_mask_axes(b) for b in range(64))


@lru_cache(maxsize=16)
def _axes(stiffness: bytes | None, stiffness_max: float, speed_limits: bytes,
          deviation_limits: bytes) -> tuple[Mode, int, tuple[float, ...]]:
    """The mode, the selection mask and the axes' limits (speed caps on the compliant
    axes, deviation limits on the others) of a command's stiffness (its bytes; ``None``:
    no command, a hold), kept for the next commands with the same. Force mode takes the
    axes whose commanded stiffness is at most ``stiffness_max``."""
    if stiffness is None:
        compliant, mode = np.zeros(6, dtype=bool), Mode.HOLD
    else:
        compliant = np.frombuffer(stiffness, dtype=np.float64) <= stiffness_max
        mode = Mode.FORCE if compliant.any() else Mode.SERVO
    limits = np.where(compliant, np.frombuffer(speed_limits, dtype=np.float64),
                      np.frombuffer(deviation_limits, dtype=np.float64))
    return mode, selection_bits(compliant), tuple(limits.tolist())  # (shared: immutable)
