"""``ffexp campaign --resume DIR``: after Ctrl-C a campaign runs only what is missing."""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from ffexp.campaign import CampaignEntry, run_campaign
from ffexp.cli import app
from ffexp.experiment import RunResult, run_file
from ffexp.rig_choice import RigChoice

ROOT = Path(__file__).resolve().parents[1]
runner = CliRunner()


def _campaign(tmp_path: Path, n: int = 3) -> Path:
    runs = "".join(f'[[runs]]\nprotocol = "{ROOT}/protocols/method2.toml"\n'
                   f'set = ["run.timeout_s=0.{i + 2}"]\n' for i in range(n))
    path = tmp_path / "camp.toml"
    path.write_text(f'name = "tiny"\n{runs}')
    return path


def test_a_stopped_campaign_resumes_with_only_the_missing_runs(tmp_path: Path) -> None:
    camp = _campaign(tmp_path)
    rig = RigChoice(driver="mock")
    started = [0]

    def stopped() -> bool:  # Ctrl-C as the second run starts
        return started[0] >= 2

    def one(entry: CampaignEntry, out_dir: Path) -> RunResult:
        started[0] += 1
        return run_file(entry.protocol, list(entry.overrides), rig=rig, out_dir=out_dir,
                        stop_requested=stopped)

    first = run_campaign(camp, rig=rig, out_parent=tmp_path / "out", run_one=one,
                         stop_requested=stopped)
    assert len(first.results) == 2  # the third never started
    assert [r.outcome.stop_reason.value for r in first.results][-1] == "stop_requested"
    kept = first.results[0].path
    result = runner.invoke(app, ["campaign", str(camp), "--driver", "mock", "--no-figures",
                                 "--resume", str(first.directory)])
    assert result.exit_code == 0, result.stderr
    manifest = json.loads((first.directory / "campaign.json").read_text())
    names = [r["recording"] for r in manifest["runs"]]
    assert len(names) == 3 and names[0] == kept.name  # the finished run is kept, not rerun
    assert all(r["end"] != "stop_requested" for r in manifest["runs"])
    assert len(list(first.directory.glob("*.mcap"))) == 4  # 1 kept, 1 stopped, 2 new


def test_resume_of_another_campaign_or_no_campaign_is_bad_input(tmp_path: Path) -> None:
    camp = _campaign(tmp_path, 1)
    done = run_campaign(camp, rig=RigChoice(driver="mock"), out_parent=tmp_path / "out")
    other = tmp_path / "other.toml"
    other.write_text(camp.read_text().replace('"tiny"', '"other"'))
    result = runner.invoke(app, ["campaign", str(other), "--driver", "mock", "--resume",
                                 str(done.directory)])
    assert result.exit_code == 2 and "another campaign file" in result.stderr
    result = runner.invoke(app, ["campaign", str(camp), "--driver", "mock", "--resume",
                                 str(tmp_path)])
    assert result.exit_code == 2 and "not a campaign directory" in result.stderr
