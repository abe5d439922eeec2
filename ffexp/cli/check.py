"""``ffexp check FILE...``: validate protocols, campaigns, rigs, scenes, sweep protocols
and studies (``ffexp reproduce --config``), and their combination, creating nothing.

Each file's kind is recognised (:mod:`ffexp.filekind`); a rig among the files (or
``--rig`` / ``--driver``) is the one every protocol and campaign is checked on. A
run protocol is checked as ``ffexp run`` checks it before its recording exists:
the protocol with its overrides, its scene, the rig, and the devices opened on
that scene and closed again (a simulator builds its world; a hardware link
resolves its addresses and binds its local port; no packet is sent, no file
written). The first fault is one ``error:`` line, exit 2.
"""

from __future__ import annotations

from pathlib import Path

import typer

from ffexp.cli._common import SCENE_SET_HELP, SET_HELP, cli_errors, with_scene_sets


@cli_errors
def check(
    files: list[Path] = typer.Argument(..., help="Run protocols, campaigns, rigs, scenes, "
                                       "sweep protocols or studies (TOML)."),
    rig: Path | None = typer.Option(None, "--rig", help="Check the protocols on this rig "
                                    "(default: a rig among FILES, else the built-in sim rig)."),
    driver: str | None = typer.Option(None, "--driver", help="Without --rig: the built-in "
                                      "rig of this driver.", show_default=False),
    set_: list[str] = typer.Option([], "--set", help=SET_HELP),
    scene_set: list[str] = typer.Option([], "--scene-set", help=SCENE_SET_HELP),
    rig_set: list[str] = typer.Option([], "--rig-set", help="Override a rig field "
                                      "(repeatable)."),
) -> None:
    """Check files and their combination (protocol with rig, scene with robot) as a run
    would before it starts; write nothing. Exit 0, or 2 at the first fault (one line).

    Example: ffexp check protocols/method2.toml rigs/sim.toml
    """
    from drivers.config import read_toml
    from ffexp.cli.run import rig_choice
    from ffexp.errors import ConfigError
    from ffexp.filekind import kind_of

    sets = with_scene_sets(set_, scene_set)
    kinds: dict[Path, str] = {}
    for path in files:
        kind = kind_of(read_toml(path))
        if kind is None:
            raise ConfigError(str(path), "", "not a protocol, campaign, rig, scene, sweep "
                              "protocol, impact protocol or study of ffexp")
        kinds[path] = kind
    rigs = [p for p, k in kinds.items() if k == "rig"]
    if rig is None and len(rigs) > 1 and any(k in ("run protocol", "campaign")
                                             for k in kinds.values()):
        raise ConfigError(str(rigs[1]), "", f"a second rig (after {rigs[0]}): check the "
                          "protocols on one rig at a time, or give it as --rig")
    on_rig = rig if rig is not None else (rigs[0] if rigs else None)
    choice = rig_choice(on_rig, driver, rig_set)
    given = on_rig is not None or driver is not None  # a scene alone is checked alone
    for path, kind in kinds.items():
        typer.echo(f"ok: {path}: {kind}{_check_one(path, kind, choice, sets, given)}")


def _check_one(path: Path, kind: str, choice: object, sets: list[str], rig_given: bool) -> str:
    """Check one file; what it was checked with (for the ok line)."""
    from drivers.config import load_model
    from drivers.description.scene import load_scene
    from ffexp.campaign import check_campaign
    from ffexp.contact1dof.sweep import SweepProtocol
    from ffexp.experiment import check_arm, load_rig_choice
    from ffexp.rig_choice import RigChoice

    assert isinstance(choice, RigChoice)
    where = f" on {choice.path}" if choice.path is not None else \
        f" on the built-in {choice.driver} rig"
    if kind == "run protocol":
        what = _open_closed(path, sets, choice)
        return where + (f" ({what})" if what else "")
    if kind == "campaign":
        _camp, entries = check_campaign(path, sets, choice)
        whats = {_open_closed(entry.protocol, list(entry.overrides), choice)
                 for entry in entries} - {""}
        return f", {len(entries)} run(s){where}" + (f" ({'; '.join(sorted(whats))})"
                                                    if whats else "")
    if kind == "rig":
        load_rig_choice(RigChoice(path=path, overrides=choice.overrides
                                  if choice.path == path else ()))
        return ""
    if kind == "scene":
        scene = load_scene(path)
        if not rig_given:
            return ""
        rig_model, source = load_rig_choice(choice)
        what = check_arm(rig_model, source, scene, str(path))
        return where + (f" ({what})" if what else "")
    if kind == "impact protocol":
        from ffexp.hil.protocol import load_hil_protocol

        load_scene(load_hil_protocol(path).scene)
        return ""
    if kind == "sweep protocol":
        load_model(SweepProtocol, path, sets)
        return ""
    if kind == "study":
        from ffexp.sweeps import reproduce as study_mod

        study_mod.load(path, sets)
    return ""


def _open_closed(protocol_path: Path, overrides: list[str], choice: object) -> str:
    """The protocol, its scene and the rig, the devices opened on that scene and closed,
    the scene's arm against the rig's robot: what ``ffexp run`` checks before its
    recording exists. What becomes of the scene's arm, in words ("" when nothing)."""
    from drivers.description.scene import load_scene
    from drivers.factory import open_devices
    from ffexp.experiment import check_arm, load_rig_choice
    from ffexp.protocol import load_run_protocol, scene_path
    from ffexp.rig_choice import RigChoice

    assert isinstance(choice, RigChoice)
    protocol = load_run_protocol(protocol_path, overrides)
    rig_model, source = load_rig_choice(choice)
    scene_file = scene_path(protocol_path, protocol)
    devices = open_devices(rig_model, source=source, scene_file=scene_file,
                           scene_overrides=protocol.scene.set, seed=protocol.seed)
    try:
        scene = devices.scene or load_scene(scene_file, protocol.scene.set)
        return check_arm(rig_model, source, scene, str(scene_file))
    finally:
        devices.close()
