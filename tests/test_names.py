"""Names never collide: runs, figures and reports of the same protocol.

A campaign that runs one protocol three times (three f_ref values) in the
same second leaves three recordings with three names, each naming its
overrides; their figures and titles differ; ``--plots`` into a directory
that already has figures adds beside them.
"""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path

import pytest
from typer.testing import CliRunner

from ffexp import figures
from ffexp.cli import app
from ffexp.cli.run import _run_title
from ffexp.naming import BASE_ID, overrides_id, reserve, run_stem
from ffexp.recording import load

ROOT = Path(__file__).resolve().parents[1]
runner = CliRunner()
F_REFS = (1.0, 1.5, 2.0)


def test_overrides_id_is_stable_and_tells_overrides_apart() -> None:
    assert overrides_id([]) == BASE_ID
    a = overrides_id(["align.f_ref=[0,0,1.0,0,0,0]"])
    b = overrides_id(["align.f_ref=[0,0,1.5,0,0,0]"])
    assert a != b and len(a) == 6 and a == overrides_id(["align.f_ref=[0,0,1.0,0,0,0]"])
    assert overrides_id(["a=1", "b=2"]) != overrides_id(["b=2", "a=1"])  # order matters
    when = datetime(2026, 11, 23, 19, 1, 2, tzinfo=UTC)
    assert run_stem("method2", [], when) == "method2-base-20261123-190102"
    assert run_stem("method2", [], when, "ur") == "method2-ur-base-20261123-190102"


def test_reserve_never_hands_out_a_name_twice(tmp_path: Path) -> None:
    paths = [reserve(tmp_path, "x", ".mcap") for _ in range(3)]
    assert [p.name for p in paths] == ["x.mcap", "x-1.mcap", "x-2.mcap"]
    assert all(p.exists() for p in paths)


@pytest.fixture(scope="module")
def same_protocol_campaign(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("same")
    camp = d / "same3.toml"
    camp.write_text('name = "same3"\n' + "".join(
        f'[[runs]]\nprotocol = "{ROOT / "protocols/method2.toml"}"\n'
        f'set = ["align.f_ref=[0,0,{f},0,0,0]"]\n' for f in F_REFS
    ))
    result = runner.invoke(app, [
        "campaign", str(camp), "--rig", str(ROOT / "rigs/mock.toml"),
        "--set", "run.timeout_s=0.2", "--out", str(d / "out"), "--no-figures",
    ])
    assert result.exit_code == 0, result.stderr
    (camp_dir,) = (d / "out").glob("same3-*")
    return camp_dir


def test_three_runs_of_one_protocol_have_three_names(same_protocol_campaign: Path) -> None:
    recs = sorted(same_protocol_campaign.glob("*.mcap"))
    assert len(recs) == 3
    ids = {p.stem.split("-")[2] for p in recs}
    assert len(ids) == 3 and BASE_ID not in ids
    assert all(p.stem.split("-")[1] == "mock" for p in recs)  # the robot that ran it
    for p in recs:
        meta = load(p).metadata["run"]
        assert p.stem.startswith("method2-") and meta["run_name"] == p.stem
        assert meta["overrides_id"] in p.stem


def test_their_figure_titles_differ(same_protocol_campaign: Path) -> None:
    recs = [load(p) for p in sorted(same_protocol_campaign.glob("*.mcap"))]
    with figures.style():
        fig = figures.campaign_figure([(_run_title(r), r) for r in recs], "same3")
    # each row is titled with its method and its own f_ref, and names its run beside
    titles = [ax.get_title(loc="left") for ax in fig.axes if ax.get_title(loc="left").startswith(
        "Method II")]
    assert len(set(titles)) == 3
    assert all(any(f"{f:g} N" in t for t in titles) for f in F_REFS)
    names = " ".join(ax.get_title(loc="left") for ax in fig.axes)
    assert all(_run_title(r) in names for r in recs)


def test_plots_into_an_existing_directory_adds(
    same_protocol_campaign: Path, tmp_path: Path
) -> None:
    recs = sorted(same_protocol_campaign.glob("*.mcap"))[:2]
    args = ["analyze", *map(str, recs), "--plots", str(tmp_path), "--json"]
    assert runner.invoke(app, args).exit_code == 0
    first = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    assert len(first) == 2 * 2 * 2  # two runs, two figures, PNG and SVG
    assert runner.invoke(app, args).exit_code == 0
    after = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    assert len(after) == 16
    assert all(after[name] == data for name, data in first.items())
