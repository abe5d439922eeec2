"""``ffexp report DIR``: one self-contained HTML page for a campaign or a sweep.

The page holds the paper's Table res_par beside ours (runs whose protocol
carries the paper's values), the summary table of every run, any CSV tables
the directory holds (a sweep's results), every figure (PNG, embedded as data
URIs; drawn from the recordings when the directory has none), the versions
and source revisions the runs were recorded with, and the protocols (the
campaign file and each run's protocol file, as recorded). Nothing is fetched
from anywhere: the page opens offline and can be mailed.

It reads at 1280 px: a table wider than the page scrolls sideways inside its
own box (the run's name stays in view), figures take the page's width, and a
click on a figure opens it at full size over the page (a small inline script;
the figure files, when the directory has them, are linked too).
"""

from __future__ import annotations

import base64
import html
import io
import json
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ffexp.analysis import (
    COMPARE_COLUMNS,
    PAPER_COLUMNS,
    compare_row,
    metrics,
    paper_row,
    run_info,
    run_name,
)
from ffexp.errors import InputError
from ffexp.naming import reserve, stamp
from ffexp.revision import source_revision

if TYPE_CHECKING:
    from ffexp.recording import Recording

#: CSV tables longer than this are data (a sweep's every sample): named, not shown.
MAX_CSV_ROWS = 60
#: Long-format data files (a sweep's every sample) are listed, not shown.
MAX_CSV_BYTES = 2_000_000

_CSS = """
body{font-family:system-ui,sans-serif;margin:2em auto;max-width:1200px;color:#222;padding:0 1em}
h1{font-size:1.5em}h2{font-size:1.2em;border-bottom:1px solid #ccc;margin-top:2em}
h1,h2,h3,p,figcaption,summary{overflow-wrap:break-word}
.scroll{overflow-x:auto;max-width:100%;margin:0.5em 0}
table{border-collapse:collapse;font-size:0.85em}
caption{text-align:left;font-size:0.9em;color:#555;padding:0 0 0.2em}
th,td{border:1px solid #ccc;padding:2px 6px;text-align:right}
td{white-space:nowrap}th{background:#f0f0f0;vertical-align:bottom}
td:first-child,th:first-child{text-align:left;position:sticky;left:0}
td:first-child{background:#fff}
.meta td{text-align:left;white-space:normal;overflow-wrap:anywhere}
figure{margin:1em 0;border:1px solid #ddd;padding:0.3em}
figure img{display:block;width:100%;height:auto;cursor:zoom-in}
figcaption{font-size:0.8em;color:#555}
figure.zoomed{position:fixed;inset:0;z-index:10;margin:0;padding:1em;background:#fff;
overflow:auto;border:0}
figure.zoomed img{width:auto;max-width:none;cursor:zoom-out}
pre{background:#f7f7f7;padding:0.5em;overflow-x:auto;font-size:0.8em}
.warn{color:#a33}
"""
#: Click a figure: it opens at full size over the page (click or Escape: back).
_JS = """
document.addEventListener('click', function (e) {
  var fig = e.target.closest('figure.fig');
  if (!fig || e.target.closest('a')) return;
  fig.classList.toggle('zoomed');
});
document.addEventListener('keydown', function (e) {
  if (e.key !== 'Escape') return;
  document.querySelectorAll('figure.zoomed').forEach(function (f) {
    f.classList.remove('zoomed');
  });
});
"""


@dataclass
class ReportInput:
    """What a directory holds for a report."""

    directory: Path
    kind: str
    manifest: dict[str, Any]
    recordings: list[Recording]
    csv_files: list[Path]
    images: list[Path]
    warnings: list[str] = field(default_factory=list)


def collect(directory: Path) -> ReportInput:
    """Read a campaign or sweep directory: its manifest, recordings, CSVs and figures.

    Raises:
        InputError: not a directory, or nothing to report in it.
    """
    from ffexp.recording import load

    if not directory.exists():
        raise InputError(f"{directory}: directory not found")
    if not directory.is_dir():
        raise InputError(f"{directory}: not a directory (a campaign or sweep directory)")
    manifest: dict[str, Any] = {}
    kind = "directory"
    for name in ("campaign.json", "sweep.json", "manifest.json"):
        path = directory / name
        if path.is_file():
            try:
                manifest = json.loads(path.read_text())
            except (json.JSONDecodeError, UnicodeDecodeError) as exc:
                raise InputError(f"{path}: not valid JSON ({exc})") from None
            if not isinstance(manifest, dict):
                raise InputError(f"{path}: expected a JSON object")
            kind = str(manifest.get("kind", name.removesuffix(".json")))
            break
    recs: list[Recording] = []
    warnings: list[str] = []
    for path in sorted(directory.rglob("*.mcap")):
        try:
            rec = load(path)
        except InputError as exc:
            warnings.append(str(exc))
            continue
        if "/estimator/state" not in rec.topics:
            warnings.append(f"{path}: not a run recording; left out")
            continue
        warnings.extend(rec.warnings)
        recs.append(rec)
    csvs = sorted(p for p in directory.rglob("*.csv") if p.is_file())
    images = sorted(p for p in directory.rglob("*.png") if p.is_file())
    if not recs and not csvs and not images:
        raise InputError(f"{directory}: no recordings, tables or figures to report")
    return ReportInput(directory, kind, manifest, recs, csvs, images, warnings)


def _cell(value: object, digits: int = 3) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    return str(value)


#: A table's columns: (title, row key), in order. To add a column, add it to the list.
Columns = Sequence[tuple[str, str]]


def _table(columns: Columns, rows: Sequence[dict[str, Any]], digits: int = 3,
           caption: str = "") -> str:
    """``rows`` as an HTML table of ``columns``, in a box that scrolls sideways when the
    table is wider than the page (the page itself never does)."""
    head = "".join(f"<th>{html.escape(t)}</th>" for t, _k in columns)
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(_cell(r.get(k), digits))}</td>" for _t, k in columns)
        + "</tr>"
        for r in rows
    )
    cap = f"<caption>{html.escape(caption)}</caption>" if caption else ""
    return _scroll(f"<table>{cap}<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>")


def _scroll(table: str) -> str:
    return f'<div class="scroll">{table}</div>'


def _csv_html(path: Path, root: Path) -> str:
    import pandas as pd

    rel = html.escape(str(path.relative_to(root)))
    if path.stat().st_size > MAX_CSV_BYTES:
        return f"<p>{rel}: {path.stat().st_size / 1e6:.1f} MB of data (not shown)</p>"
    try:
        frame = pd.read_csv(path)
    except (ValueError, UnicodeDecodeError, pd.errors.ParserError) as exc:
        return f'<p class="warn">{rel}: cannot be read as CSV ({html.escape(str(exc))})</p>'
    if len(frame) > MAX_CSV_ROWS:
        columns = html.escape(", ".join(map(str, frame.columns)))
        return (f"<p>{rel}: data, {len(frame)} rows of {columns} (not shown; the figures "
                "draw it)</p>")
    table = frame.to_html(index=False, na_rep="", float_format=lambda x: f"{x:.4g}", border=0)
    return f"<h3>{rel}</h3>{_scroll(table)}"


def _img(data: bytes, alt: str, href: str | None = None) -> str:
    """A figure at the page's full width; a click opens it at full size over the page
    (and ``href``, when given, links the image file)."""
    uri = "data:image/png;base64," + base64.b64encode(data).decode()
    link = f' (<a href="{html.escape(href)}">open the file</a>)' if href else ""
    return (f'<figure class="fig"><img src="{uri}" alt="{html.escape(alt)}" '
            f'title="click: full size"><figcaption>{html.escape(alt)}{link}; click the figure '
            "for its full size</figcaption></figure>")


def _drawn_figures(recs: Sequence[Recording], title: str) -> list[tuple[str, bytes]]:
    """The campaign figure of the recordings, drawn in memory (PNG bytes)."""
    from ffexp import figures

    if not recs:
        return []
    with figures.style():
        fig = figures.campaign_figure([(run_name(r), r) for r in recs], title)
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=figures.DPI)
    return [(f"{title}: contact wrench of every run (drawn for this report)", buf.getvalue())]


def _versions(recs: Sequence[Recording]) -> list[dict[str, Any]]:
    seen: dict[str, set[str]] = {}
    for rec in recs:
        meta = rec.metadata.get("run", {})
        try:
            versions = json.loads(meta.get("versions", "{}"))
        except json.JSONDecodeError:
            versions = {}
        versions.setdefault("source_revision", meta.get("source_revision", "(not recorded)"))
        for k, v in versions.items():
            seen.setdefault(k, set()).add(str(v))
    return [{"package": k, "versions": ", ".join(sorted(v))} for k, v in sorted(seen.items())]


def render(data: ReportInput, out_dir: Path | None = None) -> str:
    """The report as one HTML document (``out_dir``: where it will be written, for the
    links to the figure files; None: no links)."""
    name = str(data.manifest.get("name") or data.directory.name)
    now = datetime.now(UTC).isoformat(timespec="seconds")
    parts = [
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
        "<meta name='viewport' content='width=device-width, initial-scale=1'>",
        f"<title>ffexp report: {html.escape(name)}</title><style>{_CSS}</style>",
        f"<script>{_JS}</script></head><body>",
        f"<h1>ffexp report: {html.escape(name)} ({html.escape(data.kind)})</h1>",
        '<div class="scroll"><table class="meta"><tbody>',
        f"<tr><th>directory</th><td>{html.escape(str(data.directory))}</td></tr>",
        f"<tr><th>generated</th><td>{now}</td></tr>",
        f"<tr><th>report by ffexp</th><td>{html.escape(source_revision())}</td></tr>",
        f"<tr><th>runs</th><td>{len(data.recordings)}</td></tr>",
        "</tbody></table></div>",
    ]
    for w in data.warnings:
        parts.append(f'<p class="warn">warning: {html.escape(w)}</p>')
    ms = [metrics(r) for r in data.recordings]
    paper = [row for row in (paper_row(r, m) for r, m in zip(data.recordings, ms, strict=True))
             if row is not None]
    if paper:
        parts.append("<h2>The paper beside ours</h2>")
        parts.append("<p>Per run: the paper's outcome, ours, and whether they agree; the "
                     "paper's times as it gives them (its clock starts the experiment at "
                     "<em>paper start</em>), ours since the tare. The paper's values come "
                     "from each protocol's <code>[paper]</code> table; breaks are counted "
                     "after the first contact, and within ALIGN before the seat.</p>")
        cols = [(t, k) for t, k, _p in PAPER_COLUMNS]
        parts.append(_table(cols, paper, digits=3, caption="the paper (Table res_par) vs ours"))
    if data.recordings:
        parts.append("<h2>Runs</h2>")
        rows = [compare_row(r, m) for r, m in zip(data.recordings, ms, strict=True)]
        cols = [(t, k) for t, k, _p in COMPARE_COLUMNS]
        parts.append(_table(cols, rows, caption="summary of every run"))
    if data.csv_files:
        parts.append("<h2>Tables in the directory</h2>")
        parts.extend(_csv_html(p, data.directory) for p in data.csv_files)
    parts.append("<h2>Figures</h2>")
    if data.images:
        # the figures of every run together first, then each run's
        overview = [p for p in data.images if "_all_" in p.name]
        for p in [*overview, *(p for p in data.images if p not in overview)]:
            href = Path(os.path.relpath(p, out_dir)).as_posix() if out_dir else None
            parts.append(_img(p.read_bytes(), str(p.relative_to(data.directory)), href))
    else:
        for alt, png in _drawn_figures(data.recordings, name):
            parts.append(_img(png, alt))
    parts.append("<h2>Versions and source revisions</h2>")
    parts.append(_table([("package", "package"), ("versions", "versions")],
                        _versions(data.recordings), caption="as recorded in the runs"))
    parts.append("<h2>Protocols</h2>")
    for key in ("campaign_toml", "protocol_toml", "sweep_toml"):
        if isinstance(data.manifest.get(key), str):
            src = html.escape(str(data.manifest.get(key.replace("_toml", "_file"), key)))
            parts.append(f"<h3>{src}</h3><pre>{html.escape(data.manifest[key])}</pre>")
    for rec in data.recordings:
        info = run_info(rec)
        pfile = Path(str(info.get("protocol_file", ""))).name
        text = rec.attachments.get(pfile)
        overrides = info.get("overrides", "[]")
        parts.append(f"<h3>{html.escape(run_name(rec))}: {html.escape(pfile)} "
                     f"(overrides {html.escape(overrides)})</h3>")
        if text is not None:
            parts.append(f"<pre>{html.escape(text.decode(errors='replace'))}</pre>")
        resolved = _dotted_lines(info.get("protocol_resolved", {}))
        parts.append(f"<details><summary>resolved protocol</summary><pre>"
                     f"{html.escape(resolved)}</pre></details>")
    parts.append("</body></html>")
    return "\n".join(parts)


def _dotted_lines(data: Any, prefix: str = "") -> str:
    """A resolved protocol as ``dotted.key = value`` lines, a list on one line (what
    ``--set`` takes), not JSON's one number a line."""
    if isinstance(data, dict):
        return "\n".join(line for k, v in data.items()
                         if (line := _dotted_lines(v, f"{prefix}{k}.")))
    return f"{prefix[:-1]} = {json.dumps(data)}"


def write_report(directory: Path, out: Path | None = None) -> Path:
    """Write the report of ``directory``; ``out`` default: ``DIR/report-<time>.html``
    (a taken name gets ``-1``, ...). Returns the path."""
    data = collect(directory)
    page = render(data, directory if out is None else out.parent)
    if out is None:
        out = reserve(directory, f"report-{stamp(datetime.now(UTC))}", ".html")
    try:
        out.write_text(page, encoding="utf-8")
    except OSError as exc:
        raise InputError(f"{out}: cannot write: {exc.strerror}") from None
    return out
