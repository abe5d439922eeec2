"""A campaign: several run protocols in a row, into one directory with its manifest.

:func:`run_campaign` checks every protocol and the rig before anything runs,
creates ``OUT/<campaign>-<time>/`` (never an existing directory), runs each
entry with :func:`ffexp.experiment.run_file` and writes ``campaign.json``
there (the campaign file, its text, the source revision and each run's
recording and end), which ``ffexp report`` reads, as a sweep writes
``sweep.json``. A campaign stopped by Ctrl-C resumes in its directory
(``resume``): the runs that finished are kept, the others run. The CLI
(``ffexp campaign``) only adds progress, tables and figures around it.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

from drivers.description import load_scene
from ffexp.errors import InputError
from ffexp.experiment import RunResult, check_arm, load_campaign, load_rig_choice, run_file
from ffexp.naming import stamp
from ffexp.protocol import CampaignProtocol, load_run_protocol, scene_path
from ffexp.revision import source_revision
from ffexp.rig_choice import RigChoice

__all__ = ["MANIFEST", "CampaignEntry", "CampaignResult", "check_campaign", "new_directory",
           "run_campaign", "write_manifest"]

#: The manifest's file name in a campaign directory.
MANIFEST = "campaign.json"


@dataclass(frozen=True)
class CampaignEntry:
    """One run of a campaign: its protocol file, its overrides and a label for progress."""

    protocol: Path
    overrides: tuple[str, ...]
    label: str
    timeout_s: float


@dataclass(frozen=True)
class CampaignResult:
    """A finished (or stopped) campaign: where it is and the runs that ran."""

    name: str
    directory: Path
    results: tuple[RunResult, ...]
    kept: tuple[Path, ...] = ()
    """Recordings of an earlier session of a resumed campaign."""


#: Runs one entry into the campaign directory (the CLI passes one that shows progress).
RunOne = Callable[[CampaignEntry, Path], RunResult]


def check_campaign(
    campaign_file: Path, overrides: Sequence[str] = (), rig: RigChoice | None = None
) -> tuple[CampaignProtocol, list[CampaignEntry]]:
    """The campaign and its entries, every protocol (with ``overrides``) and the rig
    checked, each protocol's scene with them and its arm against the rig's robot: bad input
    is an error here, before anything runs or is written."""
    camp = load_campaign(campaign_file)
    rig_model, rig_source = load_rig_choice(rig or RigChoice())
    entries = []
    for i, entry in enumerate(camp.runs):
        path = campaign_file.parent / entry.protocol
        entry_overrides = (*entry.set, *overrides)
        protocol = load_run_protocol(path, list(entry_overrides))
        scene_file = scene_path(path, protocol)
        check_arm(rig_model, rig_source, load_scene(scene_file, protocol.scene.set),
                  str(scene_file))
        entries.append(CampaignEntry(path, entry_overrides,
                                     f"{i + 1}/{len(camp.runs)} {path.stem}",
                                     protocol.run.timeout_s))
    return camp, entries


def new_directory(parent: Path, name: str) -> Path:
    """A new directory ``parent/name`` (or ``name-1``, ...), never an existing one."""
    if parent.exists() and not parent.is_dir():
        raise InputError(f"{parent}: exists and is not a directory")
    k = 0
    while True:
        path = parent / (name if k == 0 else f"{name}-{k}")
        try:
            path.mkdir(parents=True)
        except FileExistsError:
            k += 1
            continue
        except OSError as exc:
            raise InputError(f"{parent}: cannot create a directory: {exc.strerror}") from None
        return path


def finished_runs(directory: Path, campaign_file: Path) -> list[dict[str, object]]:
    """The runs of the campaign in ``directory`` (its ``campaign.json``) that ran to their
    end, in order, up to the first that did not (stopped by Ctrl-C, or missing): what a
    resumed campaign keeps. Bad input (exit 2): no manifest, or another campaign file's."""
    path = directory / MANIFEST
    if directory.exists() and not directory.is_dir():
        raise InputError(f"--resume: {directory}: not a directory (give the campaign's "
                         "directory)")
    try:
        manifest = json.loads(path.read_text())
    except FileNotFoundError:
        raise InputError(f"--resume: {directory}: no {MANIFEST}, not a campaign "
                         "directory") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except ValueError as exc:
        raise InputError(f"{path}: cannot read: {exc}") from None
    if not isinstance(manifest, dict) or manifest.get("kind") != "campaign":
        raise InputError(f"{path}: not a campaign manifest")
    if manifest.get("campaign_toml") != campaign_file.read_text():
        raise InputError(f"--resume: {directory} ran another campaign file than "
                         f"{campaign_file} (or one since changed)")
    kept: list[dict[str, object]] = []
    for run in manifest.get("runs", []):
        if run.get("end") == "stop_requested" or not (directory / str(run.get(
                "recording", ""))).is_file():
            break
        kept.append(run)
    return kept


def write_manifest(
    directory: Path, campaign_file: Path, name: str, results: Sequence[RunResult],
    kept: Sequence[dict[str, object]] = (),
) -> Path:
    """``campaign.json``: the campaign file, its text, the source revision and the runs
    (``kept``: runs of an earlier, resumed session, first)."""
    manifest = {
        "kind": "campaign",
        "name": name,
        "campaign_file": str(campaign_file),
        "campaign_toml": campaign_file.read_text(),
        "source_revision": source_revision(),
        "runs": [*kept, *(
            {
                "recording": r.path.name,
                "protocol": r.protocol.name,
                "aligned": r.outcome.aligned,
                "end": r.outcome.stop_reason.value,
            }
            for r in results
        )],
    }
    path = directory / MANIFEST
    path.write_text(json.dumps(manifest, indent=2) + "\n")
    return path


def run_campaign(
    campaign_file: Path,
    overrides: Sequence[str] = (),
    *,
    rig: RigChoice | None = None,
    out_parent: Path = Path("runs"),
    run_one: RunOne | None = None,
    stop_requested: Callable[[], bool] = lambda: False,
    checked: tuple[CampaignProtocol, list[CampaignEntry]] | None = None,
    resume: Path | None = None,
) -> CampaignResult:
    """Run every protocol of ``campaign_file`` on ``rig`` into a new directory under
    ``out_parent`` and write its manifest; stops between runs when ``stop_requested``.

    ``checked``: what :func:`check_campaign` returned, when the caller checked first.
    The manifest is written even when a run raises, listing the runs that finished.
    ``resume``: a directory of this campaign stopped before its end: its finished runs
    are kept (:attr:`CampaignResult.kept`) and only the others run, into it.
    """
    choice = rig or RigChoice()
    camp, entries = checked or check_campaign(campaign_file, overrides, choice)
    kept: list[dict[str, object]] = []
    if resume is not None:
        kept = finished_runs(resume, campaign_file)
        directory = resume
        entries = entries[len(kept):]
    else:
        directory = new_directory(out_parent, f"{camp.name}-{stamp(datetime.now(UTC))}")

    def default_run(entry: CampaignEntry, out_dir: Path) -> RunResult:
        return run_file(entry.protocol, list(entry.overrides), rig=choice, out_dir=out_dir,
                        stop_requested=stop_requested)

    run = run_one or default_run
    results: list[RunResult] = []
    try:
        for entry in entries:
            if stop_requested():
                break
            results.append(run(entry, directory))
    finally:
        write_manifest(directory, campaign_file, camp.name, results, kept)
    return CampaignResult(camp.name, directory, tuple(results),
                          tuple(directory / str(r["recording"]) for r in kept))
