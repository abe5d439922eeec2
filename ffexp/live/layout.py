"""The Foxglove layout of a run, ``layouts/ffexp-layout.json``.

    python -m ffexp.live.layout [PATH]      # writes it (default: the repository's file)

Four views of a run, live (``ffexp run --live``) or from its recording: the
3-D scene (``/scene/rig`` and ``/tf``, seen from the robot's base), the
contact force ``f_z`` against its reference ``f_ref``, the measured wrench,
the phase (its id every cycle and its name on each change) and the events.

Panel configurations are made with the foxglove-sdk's own layout classes
(:mod:`foxglove.layouts`, so the keys are Foxglove's); they are arranged in
the file format Foxglove's "Import from file" reads and "Export" writes
(``configById`` and a split ``layout`` tree). :func:`plotted_paths` lists the
message paths the layout uses, which the tests check against the topic
registry.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
LAYOUT_FILE = ROOT / "layouts" / "ffexp-layout.json"

_AXES = ("fx", "fy", "fz", "tx", "ty", "tz")


def _config(obj: Any) -> dict[str, Any]:
    """A foxglove.layouts config object as the app's JSON (``None`` fields left out)."""
    return json.loads(obj.to_json())  # type: ignore[no-any-return]


def panels() -> dict[str, dict[str, Any]]:
    """The panels by the app's id (``Type!name``)."""
    import foxglove.layouts as fl

    series = fl.PlotSeries
    scene = fl.ThreeDeeConfig(
        follow_tf="base",
        topics={"/scene/rig": fl.BaseRendererSceneUpdateTopicSettings(visible=True)},
        layers={"grid": fl.BaseRendererGridLayerSettings(
            layer_id="foxglove.Grid", visible=True, frame_id="base", size=2.0,
            divisions=20)},
    )
    force = fl.PlotConfig(
        paths=[series(value="/estimator/state.f_z", label="f_z [N] (contact, estimated)",
                      timestamp_method="receiveTime", enabled=True),
               series(value="/control/terms.f_ref[2]", label="f_ref [N]",
                      timestamp_method="receiveTime", enabled=True, line_style="dashed")],
        show_legend=True, is_synced=True, x_axis_val="timestamp",
    )
    wrench = fl.PlotConfig(
        paths=[series(value=f"/estimator/state.wrench[{i}]", label=f"{axis} (TCF)",
                      timestamp_method="receiveTime", enabled=True)
               for i, axis in enumerate(_AXES)],
        show_legend=True, is_synced=True, x_axis_val="timestamp",
    )
    phase = fl.StateTransitionsConfig(
        paths=[fl.StateTransitionsSeries(value="/control/terms.phase", label="phase id",
                                         timestamp_method="receiveTime"),
               fl.StateTransitionsSeries(value="/runner/phase.phase", label="phase",
                                         timestamp_method="receiveTime")],
        is_synced=True,
    )
    events = fl.LogConfig(topic_to_render="/events")
    return {
        "3D!rig": _config(scene),
        "Plot!force": _config(force),
        "Plot!wrench": _config(wrench),
        "StateTransitions!phase": _config(phase),
        "RosOut!events": _config(events),
    }


def layout() -> dict[str, Any]:
    """The whole layout file: the 3-D view on the left, plots and phase on the right."""
    right = {
        "direction": "column",
        "first": "Plot!force",
        "second": {
            "direction": "column",
            "first": "Plot!wrench",
            "second": {"direction": "column", "first": "StateTransitions!phase",
                       "second": "RosOut!events", "splitPercentage": 55},
            "splitPercentage": 50,
        },
        "splitPercentage": 35,
    }
    return {
        "configById": panels(),
        "globalVariables": {},
        "userNodes": {},
        "playbackConfig": {"speed": 1},
        "layout": {"direction": "row", "first": "3D!rig", "second": right,
                   "splitPercentage": 45},
    }


def text() -> str:
    """The file's text."""
    return json.dumps(layout(), indent=2) + "\n"


def plotted_paths() -> list[str]:
    """Every message path the layout's plots and phase panel read."""
    out: list[str] = []
    for config in panels().values():
        out += [p["value"] for p in config.get("paths", [])]
    return out


def main(argv: list[str] | None = None) -> None:
    args = sys.argv[1:] if argv is None else argv
    path = Path(args[0]) if args else LAYOUT_FILE
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text())
    print(path)


if __name__ == "__main__":
    main()
