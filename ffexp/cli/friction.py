"""``ffexp friction``: residual friction of the air bed from video."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from ffexp.cli._common import CONTEXT_SETTINGS, cli_errors, new_file, positive
from ffexp.errors import InputError
from ffexp.numfmt import fixed as _fixed
from ffexp.numfmt import pm

if TYPE_CHECKING:
    from ffexp.friction.estimate import FrictionResult

app = typer.Typer(
    help="Residual friction of the air-bed target from video.",
    no_args_is_help=True,
    context_settings=CONTEXT_SETTINGS,
)


def summary(result: FrictionResult) -> str:
    """The estimate in two lines, every number to the precision its uncertainty allows."""
    e = result.estimate
    f = e.fit
    pct = round(100 * e.confidence)
    if e.significant:
        head = (
            f"mu = {pm(e.mu, e.mu_std)} ({pct}%: [{_fixed(e.mu_low, e.mu_std)}, "
            f"{_fixed(e.mu_high, e.mu_std)}])"
        )
    else:
        head = (
            f"mu < {_fixed(e.mu_upper_bound, e.mu_std)} ({pct}% upper bound; a is not "
            f"significant: mu = {pm(e.mu, e.mu_std)})"
        )
    tail = (
        f"decel {pm(f.decel_mps2, f.decel_std_mps2)} m/s², v0 {f.v_start_mps:.4f} m/s, "
        f"{f.n_frames} frames over {f.window_s:.3f} s "
        f"[{f.t_start_s:.3f}, {f.t_end_s:.3f}] s, ended: {result.interval.end_reason}, "
        f"residual {f.residual_std_m * 1e6:.2g} µm, detectable mu {e.mu_detect_limit:.2g}"
    )
    if e.mu_high < 0.0:
        tail += "\nwarning: the target speeds up (a tilted table or a push?)"
    return head + "\n" + tail


def _parse_size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(p) for p in text.lower().split("x"))
    except ValueError:
        raise InputError(f"--size: expected WIDTHxHEIGHT such as 1280x720, not {text!r}") from None
    return w, h


#: SynthConfig's fields that synth's options name otherwise.
SYNTH_OPTIONS = {"v0_mps": "--v0", "duration_s": "--duration", "width_px": "--size",
                 "height_px": "--size", "marker_dict": "--marker"}


def _check_marker(marker: str | None) -> None:
    """``--marker``: a dictionary OpenCV knows (its error names the option)."""
    if marker is None:
        return
    from drivers.vision.marker import aruco_dictionary

    try:
        aruco_dictionary(marker)
    except ValueError as exc:
        raise InputError(f"--marker: {exc}") from None


def _synth_option(field: str) -> str:
    """The option of ``synth`` that sets SynthConfig's ``field``."""
    return SYNTH_OPTIONS.get(field, f"--{field.replace('_', '-')}")


@app.command()
@cli_errors
def synth(
    out: Annotated[Path, typer.Option("--out", help="Output video (.avi; .mkv for FFV1).")],
    mu: Annotated[float, typer.Option(help="Friction coefficient (deceleration / g).")] = 0.01,
    v0: Annotated[float, typer.Option(help="Speed right after the impulse (m/s).")] = 0.2,
    duration: Annotated[float, typer.Option(help="Video length (s).")] = 3.0,
    fps: Annotated[float, typer.Option(help="Frame rate (1/s).")] = 50.0,
    size: Annotated[str, typer.Option(help="Frame size WIDTHxHEIGHT (px).")] = "1280x720",
    noise: Annotated[float, typer.Option(help="Sensor noise std (grey levels).")] = 2.0,
    seed: Annotated[int, typer.Option(help="Seed of the random generator.")] = 0,
    truth: Annotated[Path | None, typer.Option(help="Write the ground truth (JSON) here.")] = None,
    px_per_m: Annotated[float, typer.Option("--px-per-m", help="Image scale (px/m).")] = 1000.0,
    block_m: Annotated[float, typer.Option("--block-m", help="Block side (m).")] = 0.25,
    rest_s: Annotated[float, typer.Option("--rest-s", help="Time at rest first (s).")] = 0.5,
    direction_deg: Annotated[
        float, typer.Option("--direction-deg", help="Motion direction in the image (deg from +u).")
    ] = 0.0,
    blur_px: Annotated[float, typer.Option("--blur-px", help="Defocus blur sigma (px).")] = 0.0,
    exposure_s: Annotated[
        float, typer.Option("--exposure-s", help="Motion-blur exposure (s).")
    ] = 0.0,
    lighting: Annotated[
        float, typer.Option(help="Relative brightening over the video (lighting change).")
    ] = 0.03,
    marker: Annotated[
        str | None, typer.Option(help="Draw an ArUco/AprilTag marker, e.g. DICT_4X4_50.")
    ] = None,
    codec: Annotated[str, typer.Option(help="ffv1 | png (lossless) | mjpg (lossy).")] = "ffv1",
    start_px: Annotated[
        str | None,
        typer.Option("--start-px", help="Block centre at rest 'U,V' (px); default centres it."),
    ] = None,
) -> None:
    """Render a synthetic top-view video of a block sliding with known friction."""
    import numpy as np
    from pydantic import ValidationError

    from ffexp.cli.progress import Steps
    from ffexp.friction.synth import FOURCC, SynthConfig, write_video

    width, height = _parse_size(size)
    start: tuple[float, float] | None = None
    if start_px is not None:
        try:
            su, sv = (float(p) for p in start_px.split(","))
        except ValueError:
            raise InputError(f"--start-px: expected U,V in pixels, not {start_px!r}") from None
        start = (su, sv)
    if codec not in FOURCC:
        raise InputError(f"--codec: expected one of {', '.join(FOURCC)}, not {codec!r}")
    _check_marker(marker)
    try:
        cfg = SynthConfig(
            mu=mu,
            v0_mps=v0,
            duration_s=duration,
            fps=fps,
            width_px=width,
            height_px=height,
            px_per_m=px_per_m,
            block_m=block_m,
            rest_s=rest_s,
            direction_deg=direction_deg,
            noise=noise,
            blur_px=blur_px,
            exposure_s=exposure_s,
            lighting=lighting,
            marker_dict=marker,
            start_px=start,
        )
    except ValidationError as exc:
        err = exc.errors()[0]
        field = ".".join(str(p) for p in err["loc"])
        # a check across fields: those that make the block's size in the frame
        where = _synth_option(field) if field else "--block-m, --px-per-m, --size"
        msg = str(err["msg"]).removeprefix("Value error, ")
        raise InputError(f"{where}: {msg}") from None
    for path, option in ((out, "--out"), (truth, "--truth")):
        new_file(option, path)  # a directory: OpenCV would print its own lines first
    try:
        try:
            with Steps() as steps, steps.step(f"rendering {cfg.n_frames} frames"):
                result = write_video(
                    cfg,
                    out,
                    np.random.default_rng(seed),
                    codec=codec,  # type: ignore[arg-type]
                    truth_path=truth,
                )
        except BaseException:  # a video cut short (bad settings, Ctrl-C) is not left behind
            out.unlink(missing_ok=True)  # (new_file: it did not exist before)
            raise
    except ValueError as exc:  # a setting the video cannot be made with: "field: why"
        field, sep, why = str(exc).partition(": ")
        if sep and field in SynthConfig.model_fields:
            raise InputError(f"{_synth_option(field)}: {why}") from None
        raise InputError(f"{out}: {exc}") from None
    except OSError as exc:
        raise InputError(f"{truth or out}: {exc.strerror or exc}") from None
    typer.echo(
        f"wrote {out}: {cfg.n_frames} frames {width}x{height} @ {fps:g} fps, "
        f"mu {mu:g} (a = {result.decel_mps2:.5f} m/s²), impulse at {result.impulse_time_s:.3f} s"
    )


@app.command()
@cli_errors
def estimate(
    video: Annotated[Path, typer.Argument(help="Video of the target sliding (any OpenCV format).")],
    px_per_m: Annotated[
        float | None, typer.Option("--px-per-m", help="Image scale (px/m).")
    ] = None,
    object_size_m: Annotated[
        float | None,
        typer.Option("--object-size-m", help="Known target size (m): long side, or marker side."),
    ] = None,
    table_points: Annotated[
        Path | None,
        typer.Option(
            "--table-points",
            help='JSON with "image_px" (u,v pixel points) and "table_m" (the same points on '
            "the table, x,y in m), at least 4 pairs: scale by a homography.",
        ),
    ] = None,
    marker: Annotated[
        str | None, typer.Option(help="Track an ArUco/AprilTag marker of this dictionary.")
    ] = None,
    marker_id: Annotated[int | None, typer.Option("--marker-id", help="Which marker.")] = None,
    start: Annotated[float | None, typer.Option(help="Start of the fit window (s).")] = None,
    end: Annotated[float | None, typer.Option(help="End of the fit window (s).")] = None,
    fps: Annotated[float | None, typer.Option(help="Frame-rate override (1/s).")] = None,
    confidence: Annotated[float, typer.Option(help="Two-sided confidence level.")] = 0.95,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    plot: Annotated[Path | None, typer.Option(help="Write a PNG plot here.")] = None,
    record: Annotated[
        Path | None, typer.Option(help="Write the track and the result to this MCAP file.")
    ] = None,
    progress: Annotated[
        bool | None,
        typer.Option("--progress/--no-progress", help="Progress bar (default: on a terminal)."),
    ] = None,
) -> None:
    """Estimate the friction coefficient from a video of the target sliding freely."""
    from ffexp.friction.estimate import Scale, estimate_video
    from ffexp.friction.track import ProgressFn

    new_file("--record", record)  # before the tracking, not after it
    _check_marker(marker)
    positive("--fps", fps)  # (None: the video's own)
    if marker_id is not None and marker is None:
        raise InputError(f"--marker-id: {marker_id}: needs --marker DICT (the marker's "
                         "dictionary); without it the block is tracked, not a marker")
    scale = Scale(px_per_m=px_per_m, object_size_m=object_size_m, table_points=table_points)
    show = sys.stderr.isatty() if progress is None else progress

    def run(tick: ProgressFn | None) -> FrictionResult:
        return estimate_video(
            video,
            scale,
            marker_dict=marker,
            marker_id=marker_id,
            start_s=start,
            end_s=end,
            fps=fps,
            confidence=confidence,
            progress=tick,
        )

    if show:
        from rich.console import Console
        from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

        with Progress(
            TextColumn("tracking"),
            BarColumn(),
            TextColumn("{task.completed} frames"),
            TimeRemainingColumn(),
            transient=True,
            console=Console(stderr=True),
        ) as bar:
            task = bar.add_task("track", total=None)

            def tick(done: int, total: int) -> None:
                bar.update(task, completed=done, total=total or None)

            result = run(tick)
    else:
        result = run(None)
    if plot is not None:
        from ffexp.friction.plot import plot_result

        for path in plot_result(result, plot):
            print(f"figure: {path}", file=sys.stderr if as_json else sys.stdout)
    if record is not None:
        from ffexp.friction.record import record_result

        record_result(result, record)
    if as_json:
        typer.echo(json.dumps(result.to_dict()))
    else:
        typer.echo(summary(result))
