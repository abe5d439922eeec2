"""``ffexp hil``: an impact on a target rendered by a carrier robot (``docs/hil.md``).

Imports only typer and light ffexp modules at module level.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import typer

from ffexp.cli._common import EXIT_ABORTED, SCENE_SET_HELP, cli_errors


def _free(folder: Path, stem: str) -> Path:
    """``folder/stem.mcap``, or with -1, -2, ... when taken."""
    path, n = folder / f"{stem}.mcap", 0
    while path.exists():
        n += 1
        path = folder / f"{stem}-{n}.mcap"
    return path


@cli_errors
def hil(
    protocol: Path = typer.Argument(..., help="Impact protocol (protocols/hil_impact.toml)."),
    out: Path = typer.Option(Path("runs"), "--out", help="Folder for the recording."),
    scene_set: list[str] = typer.Option([], "--scene-set", help=SCENE_SET_HELP),
    set_: list[str] = typer.Option([], "--set", help="Override a protocol field, e.g. "
                                   "--set impact.speed_mps=0.05 or --set "
                                   "faults.link_lost_at_s=0.03 (repeatable)."),
    as_json: bool = typer.Option(False, "--json", help="Print the analysis as one JSON "
                                 "object (the keys of `ffexp analyze --json`)."),
) -> None:
    """Run an impact on the target rendered by the simulated carrier and record it.

    The chaser's tool, held stiff, meets the mock-up; the carrier renders the scene's
    free-floating target from its F/T sensor (the scene's [carrier] table: cycle,
    extra delay, compensation, limits). The same impact on the ideal free body is
    recorded beside it. A carrier that holds (a limit, a stale sensor, a lost link,
    an unstable loop) ends the run with the cause on one line and exit code 3.
    """
    from ffexp.cli.tables import json_line
    from ffexp.errors import ConfigError
    from ffexp.hil.analysis import analyze_recording
    from ffexp.hil.protocol import load_hil_protocol, split_sets
    from ffexp.hil.record import record_impact, run_protocol
    from ffexp.recording import load

    if out.exists() and not out.is_dir():
        raise ConfigError("--out", str(out), "exists and is not a directory")
    proto_sets, scene_sets = split_sets(set_, scene_set)
    proto = load_hil_protocol(protocol, proto_sets)
    run = run_protocol(proto, scene_sets)
    path = record_impact(run, _free(out, proto.name))
    result = analyze_recording(load(path))
    if as_json:
        typer.echo(json_line({"file": str(path), **result}))
    hold = run.rendered.hold
    if hold is not None:
        print(f"{hold.device} held at {hold.t_s:.3f} s: {hold.cause}; chaser stopped "
              f"-> {path}", file=sys.stderr)
        raise typer.Exit(EXIT_ABORTED)
    if not as_json:
        e, e0, tau = (result[k] for k in ("restitution", "true_restitution", "loop_delay_s"))
        typer.echo(f"{proto.name}: restitution {e:.3f} (free body {e0:.3f}), loop delay "
                   f"{tau * 1e3:.2f} ms -> {path}" if None not in (e, e0, tau)
                   else f"{proto.name}: no complete impact -> {path}")


def _ints(text: str) -> list[int]:
    from ffexp.errors import ConfigError

    try:
        return [int(x) for x in text.split(",")]
    except ValueError:
        raise ConfigError("--delays", text, "expected whole cycles, e.g. 0,1,2") from None


def _check_values(proto: Any, options: tuple[tuple[str, str, list[Any]], ...]) -> None:
    """Each value of each option in the protocol's scene, before any run: a value the
    scene refuses (a negative stiffness, a delay past its limit) is bad input naming the
    option, not the scene file it was put into."""
    from drivers.description.scene import load_scene
    from ffexp.errors import ConfigError

    for option, key, values in options:
        for value in values:
            try:
                load_scene(proto.scene, (*proto.scene_set, f"{key}={value}"))
            except ConfigError as exc:
                if exc.field != key:
                    raise
                raise ConfigError(option, str(value), f"{key}: {exc.message}") from None


@cli_errors
def hil_sweep(
    protocol: Path = typer.Argument(..., help="Impact protocol (protocols/hil_impact.toml)."),
    out: Path = typer.Option(..., "--out", help="Folder for the recordings, the table "
                             "(hil_sweep.csv) and the figure (hil_sweep.png)."),
    delays: str = typer.Option("0,1,2,3,4,5", "--delays",
                               help="carrier.extra_delay_cycles values, comma-separated."),
    stiffness: str = typer.Option("5000,20000,50000", "--stiffness",
                                  help="contact.stiffness values [N/m], comma-separated."),
    compensation: str = typer.Option("none,passivity,compliance", "--compensation",
                                     help="carrier.compensation values, comma-separated."),
) -> None:
    """The energy-gain curve: every delay, stiffness and compensation, recorded and analysed."""
    from ffexp.errors import ConfigError
    from ffexp.hil.protocol import load_hil_protocol
    from ffexp.hil.sweep import curve_figure, sweep

    if out.exists() and not out.is_dir():
        raise ConfigError("--out", str(out), "exists and is not a directory")
    try:
        ks = [float(x) for x in stiffness.split(",")]
    except ValueError:
        raise ConfigError("--stiffness", stiffness, "expected numbers, e.g. 5000,20000") from None
    comps = compensation.split(",")
    bad = [c for c in comps if c not in ("none", "passivity", "compliance")]
    if bad:
        raise ConfigError("--compensation", bad[0], "expected none, passivity or compliance")
    proto = load_hil_protocol(protocol)
    ds = _ints(delays)
    _check_values(proto, (("--delays", "carrier.extra_delay_cycles", ds),
                          ("--stiffness", "contact.stiffness", ks),
                          ("--compensation", "carrier.compensation", comps)))
    out.mkdir(parents=True, exist_ok=True)
    rows = sweep(proto, out, ds, ks, comps)
    fig = curve_figure(rows, out / "hil_sweep.png")
    typer.echo(f"{len(rows)} runs -> {out / 'hil_sweep.csv'}, {fig}")
