"""Docstrings, comments and docs cite only files that exist in this repository.

Every path like ``docs/conventions.md``, ``benchmarks/bench_x.py``,
``protocols/x.toml``, ``rigs/x.toml`` or ``data/...`` that a docstring or a
comment of ``ffexp/`` or ``drivers/`` cites must exist (a glob such as
``protocols/method*.toml`` must match at least one file), and no module may
point outside the repository (``../shared``, ``shared/design``). The module
and package paths that ``docs/*.md`` cite must exist too, so the architecture
page follows the tree.
"""

from __future__ import annotations

import ast
import io
import re
import tokenize
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("ffexp", "drivers")
CITED_DIRS = ("docs", "benchmarks", "protocols", "rigs", "data")
FORBIDDEN = ("../shared", "shared/design")

# A repository path: one of CITED_DIRS, not preceded by a path character (so
# ``../data/x`` and ``foo/docs/x`` are not read as repository paths).
_PATH = re.compile(r"(?<![\w./-])(?:" + "|".join(CITED_DIRS) + r")/[\w*.\-/]*[\w*]")
# In docs/*.md: backticked paths of the packages, tests and the cited dirs.
_DOC_PATH = re.compile(r"`((?:ffexp|drivers|tests|" + "|".join(CITED_DIRS) + r")/[\w*.\-/]*)`")


def docstrings_and_comments(source: str) -> list[tuple[int, str]]:
    """(line, text) of every docstring-like string statement and every comment."""
    out: list[tuple[int, str]] = []
    for node in ast.walk(ast.parse(source)):
        if (
            isinstance(node, ast.Expr)
            and isinstance(node.value, ast.Constant)
            and isinstance(node.value.value, str)
        ):
            out.append((node.lineno, node.value.value))
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            out.append((tok.start[0], tok.string))
    return out


def cited_paths(text: str) -> list[str]:
    """Repository paths cited in ``text`` (trailing punctuation dropped)."""
    return [path for _offset, path in cited_paths_at(text)]


def cited_paths_at(text: str) -> list[tuple[int, str]]:
    """Like :func:`cited_paths`, with the line offset of each path in ``text``."""
    return [(text.count("\n", 0, m.start()), m.group(0).rstrip(".")) for m in _PATH.finditer(text)]


def path_exists(cited: str) -> bool:
    """A cited path exists; a glob matches at least one file; a trailing ``/`` is a folder."""
    if "*" in cited:
        return any(ROOT.glob(cited))
    return (ROOT / cited).exists()


def modules() -> list[Path]:
    return sorted(p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py"))


# --------------------------------------------------------------------------- the extractor


SYNTHETIC = '''"""Module doc: signs in docs/conventions.md, see also ../data/scenes/x.toml."""

X = "docs/not_a_docstring.md"  # measured in benchmarks/bench_recording.py.


def f() -> None:
    """Run protocols/method*.toml or rigs/lab.toml; sample data/video/a.avi, done."""
    y = 1  # nothing here: mydocs/x.md, foo/data/y
'''


def test_extractor_finds_docstring_and_comment_paths_only() -> None:
    found = [p for _line, text in docstrings_and_comments(SYNTHETIC) for p in cited_paths(text)]
    assert sorted(found) == sorted(
        [
            "docs/conventions.md",
            "benchmarks/bench_recording.py",
            "protocols/method*.toml",
            "rigs/lab.toml",
            "data/video/a.avi",
        ]
    )


def test_existence_check_fails_on_a_missing_path() -> None:
    assert path_exists("docs/conventions.md")
    assert path_exists("protocols/method*.toml")
    assert not path_exists("docs/no_such_page.md")
    assert not path_exists("protocols/no_such_*.toml")


def test_line_of_a_cited_path() -> None:
    assert cited_paths_at("one\ntwo docs/a.md\n\nthree rigs/b.toml.") == [
        (1, "docs/a.md"),
        (3, "rigs/b.toml"),
    ]


def test_forbidden_references_are_found() -> None:
    assert [bad for bad in FORBIDDEN if bad in "see ../shared/design/ARCHITECTURE.md"] == list(
        FORBIDDEN
    )


def test_doc_path_pattern() -> None:
    text = "see `ffexp/loop.py`, `drivers/base/`, `rigs/*.toml`, `drivers.base` and `x/y.py`"
    assert _DOC_PATH.findall(text) == ["ffexp/loop.py", "drivers/base/", "rigs/*.toml"]


# --------------------------------------------------------------------------- the repository


def test_every_cited_path_exists() -> None:
    missing = []
    for path in modules():
        source = path.read_text(encoding="utf-8")
        for line, text in docstrings_and_comments(source):
            for offset, cited in cited_paths_at(text):
                if not path_exists(cited):
                    missing.append(f"{path.relative_to(ROOT)}:{line + offset}: {cited}")
    assert not missing, "cited paths that do not exist:\n" + "\n".join(missing)


def test_no_module_points_outside_the_repository() -> None:
    found = []
    for path in modules():
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if any(bad in line for bad in FORBIDDEN):
                found.append(f"{path.relative_to(ROOT)}:{n}: {line.strip()}")
    assert not found, "use docs/conventions.md or docs/architecture.md:\n" + "\n".join(found)


@pytest.mark.parametrize("page", ["conventions.md", "architecture.md"])
def test_docs_cite_existing_paths(page: str) -> None:
    text = (ROOT / "docs" / page).read_text(encoding="utf-8")
    missing = [p for p in _DOC_PATH.findall(text) if "<" not in p and not path_exists(p)]
    assert not missing, f"docs/{page} cites paths that do not exist: {missing}"


# --------------------------------------------------------------------------- the README


def readme() -> str:
    return (ROOT / "README.md").read_text(encoding="utf-8")


def test_quick_start_is_two_commands() -> None:
    text = readme()
    quick = text[text.index("## Quick start"):text.index("## What is here")]
    blocks = re.findall(r"```bash\n(.*?)```", quick, flags=re.S)
    assert len(blocks) == 2 and all(b.count("\n") == 1 for b in blocks)
    assert "ffexp campaign protocols/paper.toml" in blocks[0]


def test_every_command_in_the_readme_table_exists() -> None:
    from typer.testing import CliRunner

    from ffexp.cli import app

    text = readme()
    table = text[text.index("| command | what it does |"):text.index("### Exit codes")]
    commands = re.findall(r"^\| `ffexp ([a-z-]+(?: [a-z0-9-]+)?)", table, flags=re.M)
    assert len(commands) >= 12
    for command in commands:
        words = command.split()
        if words[0] in ("simulate", "friction"):
            args = words[:2]
        else:
            args = words[:1]
        result = CliRunner().invoke(app, [*args, "-h"])
        assert result.exit_code == 0, (command, result.output)


def test_the_exit_code_table_matches_the_code() -> None:
    from ffexp.cli import _common as c

    text = readme()
    table = text[text.index("| code | meaning |"):]
    codes = re.findall(r"^\| (\d+|128\+N) \|", table, flags=re.M)
    assert codes == [str(c.EXIT_OK), str(c.EXIT_FAILURE), str(c.EXIT_BAD_INPUT),
                     str(c.EXIT_ABORTED), str(c.EXIT_TIMED_OUT), f"{c.EXIT_SIGNAL_BASE}+N"]
