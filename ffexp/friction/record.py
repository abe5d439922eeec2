"""Write a friction estimate (track and result) to MCAP, JSON-encoded.

Topics:

- ``/friction/track``: one message per frame, log time = frame time in ns;
- ``/friction/result``: one message with :meth:`FrictionResult.to_dict`,
  logged at the end of the fit window.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from mcap.writer import Writer

from ffexp.errors import InputError
from ffexp.friction.estimate import FrictionResult

_NUM_OR_NULL: dict[str, Any] = {"type": ["number", "null"]}

TRACK_SCHEMA: dict[str, Any] = {
    "type": "object",
    "title": "ffexp.friction.TrackSample",
    "properties": {
        "frame": {"type": "integer"},
        "t_s": {"type": "number"},
        "valid": {"type": "boolean"},
        "in_window": {"type": "boolean"},
        "u_px": _NUM_OR_NULL,
        "v_px": _NUM_OR_NULL,
        "x_m": _NUM_OR_NULL,
        "y_m": _NUM_OR_NULL,
        "s_m": {**_NUM_OR_NULL, "description": "position along the motion direction"},
    },
    "required": ["frame", "t_s", "valid"],
}

RESULT_SCHEMA: dict[str, Any] = {
    "type": "object",
    "title": "ffexp.friction.Result",
    "properties": {
        "mu": {"type": "number"},
        "mu_std": {"type": "number"},
        "mu_upper_bound": {"type": "number"},
        "significant": {"type": "boolean"},
        "decel_mps2": {"type": "number"},
        "v0_mps": {"type": "number"},
        "window_s": {"type": "number"},
        "frames_used": {"type": "integer"},
    },
    "required": ["mu", "mu_std", "mu_upper_bound", "significant", "decel_mps2"],
}


def _num(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def record_result(result: FrictionResult, out: Path) -> None:
    """Write the track and the result of ``result`` to the MCAP file ``out``.

    Raises:
        InputError: ``out`` cannot be written.
    """
    try:
        stream = out.open("wb")
    except OSError as exc:
        raise InputError(f"{out}: cannot write ({exc.strerror or exc})") from None
    with stream:
        writer = Writer(stream)
        writer.start(profile="", library="ffexp")
        try:
            track_schema = writer.register_schema(
                "ffexp.friction.TrackSample", "jsonschema", json.dumps(TRACK_SCHEMA).encode()
            )
            result_schema = writer.register_schema(
                "ffexp.friction.Result", "jsonschema", json.dumps(RESULT_SCHEMA).encode()
            )
            track_ch = writer.register_channel(
                "/friction/track", "json", track_schema, {"video": result.video}
            )
            result_ch = writer.register_channel("/friction/result", "json", result_schema)
            tr = result.track
            in_window = set(int(i) for i in result.window_idx)
            for i, t in enumerate(tr.t_s):
                ns = round(float(t) * 1e9)
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
                writer.add_message(track_ch, ns, json.dumps(msg).encode(), ns, sequence=i)
            end_ns = round(result.estimate.fit.t_end_s * 1e9)
            writer.add_message(result_ch, end_ns, json.dumps(result.to_dict()).encode(), end_ns)
        finally:
            writer.finish()  # type: ignore[no-untyped-call]
