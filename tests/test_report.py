"""``ffexp report DIR``: one self-contained HTML page for a campaign.

The page is parsed (tables, rows, embedded images, nothing fetched from
elsewhere); when Chromium is installed (Debian's package ``chromium``; CI
installs it) it is also rendered headless at 1280 px: its DOM must hold the
same tables and images, nothing may stick out of the page's width (wide
tables scroll inside their own box) and the figures take the page's width.
Without Chromium those tests skip and say why.
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


def test_report_sets_the_papers_outcome_beside_ours_with_its_own_times(
    report_path: Path
) -> None:
    """The paper's table carries each run's outcome in the paper's words, ours and an
    agree mark, and the paper's times as it gives them (11.5 s, not 12)."""
    text = report_path.read_text()
    for header in ("<th>paper</th>", "<th>ours</th>", "<th>agree</th>", "<th>breaks ALIGN</th>"):
        assert header in text
    for cell in ("<td>11.5</td>", "<td>12.5</td>", "<td>17.5</td>", "<td>19.5</td>",
                 "<td>contact kept breaking</td>", "<td>held contact, did not slide</td>"):
        assert cell in text, cell


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


CHROMIUM = shutil.which("chromium")
#: The page width the report must read at (px).
PAGE_PX = 1280
#: Run in the page once it has loaded: what sticks out of the page's width, leaving
#: out what sits inside a box that scrolls or clips sideways (a wide table in its
#: scroll box is fine; the box itself must fit).
OVERFLOW_PROBE = """
<script>
window.addEventListener('load', function () {
  var width = document.documentElement.clientWidth, bad = [];
  function scrolls(el) {
    for (var p = el.parentElement; p && p !== document.body; p = p.parentElement) {
      var x = getComputedStyle(p).overflowX;
      if (x === 'auto' || x === 'scroll' || x === 'hidden') return true;
    }
    return false;
  }
  document.body.querySelectorAll('*').forEach(function (el) {
    var r = el.getBoundingClientRect();
    if ((r.width || r.height) && (r.right > width + 0.5 || r.left < -0.5) && !scrolls(el))
      bad.push(el.tagName + '.' + el.className + ' ' + Math.round(r.left) + '..' +
               Math.round(r.right));
  });
  var out = document.createElement('pre');
  out.id = 'probe';
  out.textContent = 'PROBE ' + JSON.stringify({
    scrollWidth: document.documentElement.scrollWidth, clientWidth: width,
    figures: Array.prototype.map.call(document.querySelectorAll('figure img'),
                                      function (i) { return i.getBoundingClientRect().width; }),
    bad: bad}) + ' END';
  document.body.appendChild(out);
});
</script>
"""


def rendered(page: Path, tmp_path: Path, width_px: int = PAGE_PX) -> tuple[str, dict[str, object]]:
    """The DOM headless Chromium renders from ``page`` at ``width_px``, and what the
    probe measured in it."""
    import json
    import re

    assert CHROMIUM is not None
    probe = tmp_path / page.name
    probe.write_text(page.read_text().replace("</body>", OVERFLOW_PROBE + "</body>"))
    done = subprocess.run(
        [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu",
         f"--user-data-dir={tmp_path / 'profile'}", f"--window-size={width_px},900",
         "--virtual-time-budget=10000", "--dump-dom", probe.as_uri()],
        capture_output=True, text=True, timeout=180,
    )
    assert done.returncode == 0, done.stderr[-500:]
    found = re.search(r"PROBE (\{.*?\}) END", done.stdout)
    assert found is not None, "the probe did not run: " + done.stdout[-300:]
    return done.stdout, json.loads(html.unescape(found.group(1)))


@pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed (Debian: apt-get "
                    "install chromium); the report's rendering at 1280 px is not checked")
def test_report_reads_at_1280_px_in_headless_chromium(report_path: Path, tmp_path: Path) -> None:
    dom, probe = rendered(report_path, tmp_path)
    page = Page()
    page.feed(dom)
    assert page.tables == 4 and page.images
    assert probe["bad"] == [], probe["bad"]
    assert probe["scrollWidth"] <= probe["clientWidth"] <= PAGE_PX  # type: ignore[operator]
    # the figures take the page's width (less its margins), no thumbnails
    assert min(probe["figures"]) >= 0.85 * probe["clientWidth"]  # type: ignore[arg-type, operator]


@pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed (Debian: apt-get "
                    "install chromium); the overflow probe is not checked")
def test_the_probe_sees_a_page_that_overflows(report_path: Path, tmp_path: Path) -> None:
    """The probe is no formality: the same report with a table out of its scroll box
    is found to stick out of the page."""
    wide = tmp_path / "wide" / report_path.name
    wide.parent.mkdir()
    text = report_path.read_text()
    wide.write_text(text.replace('<div class="scroll">', "<div>"))
    _dom, probe = rendered(wide, tmp_path)
    assert probe["bad"] and probe["scrollWidth"] > probe["clientWidth"]  # type: ignore[operator]
