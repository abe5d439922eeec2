"""The target tracker: camera calibration and checks.

Light at module level (typer and the standard library only); each command
imports what it needs inside. ``COMMANDS`` lists ``(name, function)`` pairs
that :mod:`ffexp.cli` mounts as top-level commands.

``ffexp calibrate-camera POINTS OUT [--plane-z-m Z]``: the camera-to-table
homography from four or more reference points, a CSV with the columns
``u, v, x, y`` (pixel, and base-frame metres on the marker's plane; a header
line is optional), written as the calibration file a rig's
``tracker.calibration`` names; prints the fit's residual per point.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import typer

from ffexp.cli._common import cli_errors, new_file


def _points(path: Path) -> tuple[Any, Any]:
    import csv
    import math

    import numpy as np

    from drivers.config import not_regular
    from ffexp.errors import InputError

    odd = not_regular(path)
    if odd:
        raise InputError(f"{path}: is {odd}, not a regular CSV file")
    try:
        text = path.read_text()
    except OSError as exc:
        raise InputError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a text file (a CSV of u, v, x, y)") from None
    rows = []
    for k, row in enumerate(csv.reader(text.splitlines()), start=1):
        if not row or row[0].strip().startswith("#"):
            continue
        try:
            vals = [float(v) for v in row]
        except ValueError:
            if k == 1:
                continue  # a header
            raise InputError(f"{path}: line {k}: not four numbers u, v, x, y") from None
        if len(vals) != 4:
            raise InputError(f"{path}: line {k}: needs four columns u, v, x, y")
        if not all(math.isfinite(v) for v in vals):
            raise InputError(f"{path}: line {k}: u, v, x, y must be finite numbers")
        rows.append(vals)
    arr = np.asarray(rows, np.float64).reshape(-1, 4)
    if arr.shape[0] < 4:
        raise InputError(f"{path}: needs at least four reference points, has {arr.shape[0]}")
    return arr[:, :2], arr[:, 2:]


@cli_errors
def calibrate_camera(
    points: Path = typer.Argument(..., help="CSV of reference points: u, v (pixels), x, y "
                                  "(base frame, m) on the marker's plane."),
    out: Path = typer.Argument(..., help="The calibration file to write (TOML)."),
    plane_z_m: float = typer.Option(0.0, "--plane-z-m", help="Height of the marker's plane "
                                    "in the base frame [m]."),
) -> None:
    """Camera-to-table calibration (a homography) from reference points."""
    import numpy as np

    from drivers.vision.calibration import calibration_from_points, save_calibration
    from ffexp.errors import InputError

    px, plane = _points(points)
    new_file("", out)  # before the fit and the file
    try:
        hom = calibration_from_points(px, plane)
    except ValueError as exc:
        raise InputError(f"{points}: {exc}") from None
    from drivers.vision.calibration import Calibration

    back = Calibration(hom, plane_z_m).to_plane(px)
    residual_mm = np.hypot(*(back - plane).T) * 1000.0
    try:
        save_calibration(out, hom, plane_z_m, f"ffexp calibrate-camera {points}")
    except OSError as exc:
        raise InputError(f"{out}: cannot write: {exc.strerror or exc}") from None
    for (u, v), r in zip(px, residual_mm, strict=True):
        typer.echo(f"  ({u:7.1f}, {v:7.1f}) px: residual {r:.2f} mm")
    typer.echo(f"calibration: {out} ({len(px)} points, largest residual "
               f"{float(residual_mm.max()):.2f} mm)")


COMMANDS: list[tuple[str, Callable[..., Any]]] = [("calibrate-camera", calibrate_camera)]
