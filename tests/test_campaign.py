"""``ffexp.campaign``: a campaign as a library call, its directory and manifest."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from ffexp.campaign import CampaignEntry, check_campaign, new_directory, run_campaign
from ffexp.errors import ConfigError, FfexpError, InputError
from ffexp.experiment import RunResult, run_file
from ffexp.rig_choice import RigChoice

ROOT = Path(__file__).resolve().parents[1]
MOCK = RigChoice(driver="mock")


def _campaign(tmp_path: Path, n: int = 2) -> Path:
    runs = "".join(f'[[runs]]\nprotocol = "{ROOT}/protocols/method2.toml"\n'
                   f'set = ["run.timeout_s=0.{i + 2}"]\n' for i in range(n))
    path = tmp_path / "camp.toml"
    path.write_text(f'name = "tiny"\n{runs}')
    return path


def test_run_campaign_writes_runs_and_manifest(tmp_path: Path) -> None:
    done = run_campaign(_campaign(tmp_path), rig=MOCK, out_parent=tmp_path / "out")
    assert done.directory.parent == tmp_path / "out" and done.directory.name.startswith("tiny-")
    assert len(done.results) == 2 and all(r.path.parent == done.directory for r in done.results)
    manifest = json.loads((done.directory / "campaign.json").read_text())
    assert manifest["kind"] == "campaign" and manifest["name"] == "tiny"
    assert [r["recording"] for r in manifest["runs"]] == [r.path.name for r in done.results]
    assert "run.timeout_s=0.3" in manifest["campaign_toml"]


def test_a_second_campaign_never_reuses_a_directory(tmp_path: Path) -> None:
    first = new_directory(tmp_path, "c")
    second = new_directory(tmp_path, "c")
    assert (first.name, second.name) == ("c", "c-1")


def test_a_stop_between_runs_keeps_what_ran(tmp_path: Path) -> None:
    calls: list[CampaignEntry] = []

    def one(entry: CampaignEntry, out_dir: Path) -> RunResult:
        calls.append(entry)
        return run_file(entry.protocol, list(entry.overrides), rig=MOCK, out_dir=out_dir)

    done = run_campaign(_campaign(tmp_path, 3), rig=MOCK, out_parent=tmp_path,
                        run_one=one, stop_requested=lambda: len(calls) >= 1)
    assert len(calls) == 1 and len(done.results) == 1
    manifest = json.loads((done.directory / "campaign.json").read_text())
    assert len(manifest["runs"]) == 1


def test_a_failing_run_still_leaves_the_manifest_of_those_before(tmp_path: Path) -> None:
    def one(entry: CampaignEntry, out_dir: Path) -> RunResult:
        if entry.label.startswith("2/"):
            raise FfexpError("device lost")
        return run_file(entry.protocol, list(entry.overrides), rig=MOCK, out_dir=out_dir)

    with pytest.raises(FfexpError, match="device lost"):
        run_campaign(_campaign(tmp_path), rig=MOCK, out_parent=tmp_path / "o", run_one=one)
    (camp,) = (tmp_path / "o").iterdir()
    assert len(json.loads((camp / "campaign.json").read_text())["runs"]) == 1


def test_bad_input_is_found_before_anything_is_written(tmp_path: Path) -> None:
    path = _campaign(tmp_path)
    with pytest.raises(ConfigError, match="colour"):
        check_campaign(path, ["colour=1"], MOCK)
    with pytest.raises(ConfigError, match="--driver"):
        run_campaign(path, rig=RigChoice(driver="telepathy"), out_parent=tmp_path / "never")
    assert not (tmp_path / "never").exists()
    (tmp_path / "file").write_text("")
    with pytest.raises(InputError, match="not a directory"):
        new_directory(tmp_path / "file", "c")
