"""``ffexp report DIR``: one self-contained HTML page for a campaign.

The page is parsed (tables, rows, embedded images, nothing fetched from
elsewhere); when Chromium is installed it is also opened headless and its
rendered DOM must hold the same tables and images (CI has no Chromium:
that test skips there).
"""

from __future__ import annotations

import html
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import pytest
from typer.testing import CliRunner

from ffexp.cli import app
from ffexp.revision import source_revision

ROOT = Path(__file__).resolve().parents[1]
runner = CliRunner()


class Page(HTMLParser):
    """Counts what a report is made of."""

    def __init__(self) -> None:
        super().__init__()
        self.tables = 0
        self.rows_by_table: list[int] = []
        self.images: list[str] = []
        self.external: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        if tag == "table":
            self.tables += 1
            self.rows_by_table.append(0)
        elif tag == "tr" and self.rows_by_table:
            self.rows_by_table[-1] += 1
        elif tag == "img":
            self.images.append(a.get("src") or "")
        for key in ("src", "href"):
            value = a.get(key) or ""
            if value.startswith(("http:", "https:", "//")):
                self.external.append(value)


@pytest.fixture(scope="module")
def campaign_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("report")
    result = runner.invoke(app, [
        "campaign", str(ROOT / "protocols/paper.toml"), "--rig", str(ROOT / "rigs/mock.toml"),
        "--set", "run.timeout_s=0.2", "--out", str(out), "--no-figures",
    ])
    assert result.exit_code == 0, result.stderr
    (camp,) = out.glob("paper-*")
    return camp


@pytest.fixture(scope="module")
def report_path(campaign_dir: Path) -> Path:
    result = runner.invoke(app, ["report", str(campaign_dir)])
    assert result.exit_code == 0, result.stderr
    path = Path(result.stdout.strip().removeprefix("report: "))
    assert path.parent == campaign_dir and path.suffix == ".html"
    return path


def test_report_holds_the_tables_figures_versions_and_protocols(
    campaign_dir: Path, report_path: Path
) -> None:
    text = report_path.read_text()
    page = Page()
    page.feed(text)
    n_runs = len(list(campaign_dir.glob("*.mcap")))
    assert n_runs == 5  # protocols/paper.toml
    # meta, the paper's table beside ours, the runs, the versions
    assert page.tables == 4
    assert page.rows_by_table[1] == 1 + n_runs and page.rows_by_table[2] == 1 + n_runs
    assert page.images and all(s.startswith("data:image/png;base64,") for s in page.images)
    assert page.external == []
    assert source_revision() in text
    for rec in campaign_dir.glob("*.mcap"):
        assert rec.stem in text
    shown = html.unescape(text)
    assert "[[runs]]" in shown and 'protocol = "method2.toml"' in shown  # the campaign file
    assert "paper contact [s]" in text


def test_a_second_report_does_not_overwrite_the_first(
    campaign_dir: Path, report_path: Path
) -> None:
    before = report_path.read_bytes()
    result = runner.invoke(app, ["report", str(campaign_dir)])
    assert result.exit_code == 0
    second = Path(result.stdout.strip().removeprefix("report: "))
    assert second != report_path and report_path.read_bytes() == before


@pytest.mark.skipif(shutil.which("chromium") is None, reason="Chromium is not installed")
def test_report_renders_in_headless_chromium(report_path: Path, tmp_path: Path) -> None:
    done = subprocess.run(
        ["chromium", "--headless", "--no-sandbox", "--disable-gpu", "--dump-dom",
         report_path.as_uri()],
        capture_output=True, text=True, timeout=120,
    )
    assert done.returncode == 0, done.stderr[-500:]
    page = Page()
    page.feed(done.stdout)
    assert page.tables == 4 and page.images
