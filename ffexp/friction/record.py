"""Write a friction estimate (track and result) to MCAP through the run recorder.

The topics and their JSON schemas are registered in
:mod:`ffexp.recording.topics` like every other topic:

- ``/friction/track``: one message per frame, log time = frame time in ns;
- ``/friction/result``: one message with :meth:`FrictionResult.to_dict`,
  logged at the end of the fit window.

The video the estimate came from is stored as MCAP metadata ``friction``
(``{"video": ...}``).
"""

from __future__ import annotations

import math
from pathlib import Path

from ffexp.friction.estimate import FrictionResult
from ffexp.recording.recorder import Recorder

TRACK_TOPIC = "/friction/track"
RESULT_TOPIC = "/friction/result"


def _num(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def record_result(result: FrictionResult, out: Path) -> None:
    """Write the track and the result of ``result`` to the MCAP file ``out``.

    Raises:
        InputError: ``out`` cannot be written.
    """
    with Recorder(out) as rec:
        rec.metadata("friction", {"video": result.video})
        tr = result.track
        in_window = {int(i) for i in result.window_idx}
        for i, t in enumerate(tr.t_s):
            msg = {
                "frame": i,
                "t_s": float(t),
                "valid": bool(tr.valid[i]),
                "in_window": i in in_window,
                "u_px": _num(tr.centre_px[i, 0]),
                "v_px": _num(tr.centre_px[i, 1]),
                "x_m": _num(result.pos_m[i, 0]),
                "y_m": _num(result.pos_m[i, 1]),
                "s_m": _num(result.s_m[i]),
            }
            rec.write_json(TRACK_TOPIC, round(float(t) * 1e9), msg)
        end_ns = round(result.estimate.fit.t_end_s * 1e9)
        rec.write_json(RESULT_TOPIC, end_ns, result.to_dict())
