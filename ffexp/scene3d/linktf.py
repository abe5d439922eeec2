"""The links' ``/tf`` messages of a cycle, written out for a chain of +-y and +-z joints.

``/tf`` carries each link in its parent as a translation and a unit quaternion
(:meth:`Recorder.encode_transform <ffexp.recording.Recorder.encode_transform>`, the
quaternion by Shepperd's method from the rows of the link's 4x4). For a joint about
+-z or +-y whose parent offset is a plain translation (a chain
:func:`~ffexp.scene3d.kinematics.link_rows` writes out: the LWR4+), most entries of
those rows are the constants 0 and 1, so most of the method's operations have a
known result: ``0.0 - 0.0`` is ``0.0``, ``s - (-s)`` is ``s + s``, the translation is
the joint's origin. :class:`LinkTransforms` does only the operations left, in the
same order (the same IEEE results), and formats the constant parts of each message
once: the messages are byte for byte those of ``encode_transform`` on ``link_rows``
(``tests/test_scene3d.py``). A link whose rows take the method's other branch
(trace <= 0: a joint turned beyond about 120 deg), the first link when the arm's
base moves it, and a chain that is not written out go the general way.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence

import numpy as np

from drivers.base.types import F64, NS_PER_S
from drivers.description.arm import ArmDescription
from ffexp.scene3d.kinematics import _angles, _joint_rows, _written_out, link_rows

__all__ = ["LinkTransforms"]

#: ``encode_transform(log_ns, parent, child, rows)``.
Encode = Callable[[int, str, str, list[list[float]]], bytes]

_Z, _Y = 2, 1


class LinkTransforms:
    """Every link's ``/tf`` message of one cycle, from the joint positions.

    Args:
        arm: the chain.
        base: the arm's base in the robot's frame (moves ``link1``), or ``None``.
        frames: the links' frame names (``link1`` ..).
        encode: the recorder's ``encode_transform`` (the general way).
    """

    def __init__(self, arm: ArmDescription, base: F64 | None, frames: Sequence[str],
                 encode: Encode) -> None:
        self.arm = arm
        self.base = base
        self.frames = tuple(frames)
        self.parents = ("base", *self.frames[:-1])
        self.encode = encode
        # per link: (axis index, its sign, the message's constant middle) or None (general)
        self._links: list[tuple[int, float, str] | None] = []
        written = _written_out(arm)
        for i in range(arm.joints):
            axis = arm.joint_axes[i]
            x, y, z = (float(v) for v in arm.joint_origins_m[i])
            general = (not written or (i == 0 and base is not None)
                       or not all(math.isfinite(v) for v in (x, y, z)))
            if general:
                self._links.append(None)
                continue
            k = _Z if axis[2] else _Y
            middle = (f'"parent_frame_id":{json.dumps(self.parents[i])},'
                      f'"child_frame_id":{json.dumps(self.frames[i])},'
                      f'"translation":{{"x":{x!r},"y":{y!r},"z":{z!r}}},"rotation":{{"x":')
            self._links.append((k, axis[k], middle))
        self._written = written

    def messages(self, log_ns: int, q_rad: Sequence[float] | F64) -> list[bytes]:
        """The links' messages at log time ``log_ns``, ``link1`` first."""
        encode = self.encode
        if not self._written:
            return [encode(log_ns, parent, frame, rows) for parent, frame, rows in zip(
                self.parents, self.frames, link_rows(q_rad, self.base, self.arm), strict=True)]
        q = _angles(q_rad, self.arm)
        sec, nsec = divmod(log_ns, NS_PER_S)
        stamp = f'{{"timestamp":{{"sec":{sec},"nsec":{nsec}}},'
        out: list[bytes] = []
        cos, sin, sqrt, isfinite = math.cos, math.sin, math.sqrt, math.isfinite
        for i, link in enumerate(self._links):
            if link is not None:
                k, sign, middle = link
                c, s = cos(q[i]), sin(q[i])
                s *= sign
                # the trace of the rows, summed as rows_floats sums it
                tr = c + c + 1.0 if k == _Z else c + 1.0 + c
                if tr > 0.0:
                    root = 2.0 * sqrt(tr + 1.0)
                    turn = (s - -s) / root
                    w = 0.25 * root
                    if isfinite(turn) and isfinite(w):
                        if k == _Z:
                            text = f'{stamp}{middle}0.0,"y":0.0,"z":{turn!r},"w":{w!r}}}}}'
                        else:
                            text = f'{stamp}{middle}0.0,"y":{turn!r},"z":0.0,"w":{w!r}}}}}'
                        out.append(text.encode())
                        continue
            rows = _joint_rows(self.arm.joint_origins_m[i], self.arm.joint_axes[i], q[i])
            if i == 0 and self.base is not None:
                rows = (self.base @ np.array(rows)).tolist()
            out.append(encode(log_ns, self.parents[i], self.frames[i], rows))
        return out
