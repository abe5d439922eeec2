"""Docstrings, comments and docs cite only files and names that exist in this repository.

Every path like ``docs/conventions.md``, ``benchmarks/bench_x.py``,
``protocols/x.toml``, ``rigs/x.toml`` or ``data/...`` that a docstring or a
comment of ``ffexp/`` or ``drivers/`` cites must exist (a glob such as
``protocols/method*.toml`` must match at least one file), and no module may
point outside the repository (``../shared``, ``shared/design``). The pages
(README.md, every ``docs/**/*.md``, ``benchmarks/README.md``) may cite only
paths that exist, link only to files that exist, and name only modules,
classes, functions and attributes (``ffexp.recording.load``,
``drivers.errors.FfexpError``) that exist, so the docs follow the tree. The
README stays short, with its two Quick start commands.
"""

from __future__ import annotations

import ast
import importlib
import inspect
import io
import re
import tokenize
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("ffexp", "drivers")
CITED_DIRS = ("docs", "benchmarks", "protocols", "rigs", "data")
FORBIDDEN = ("../shared", "shared/design")

# A repository path: one of CITED_DIRS, not preceded by a path character (so
# ``../data/x`` and ``foo/docs/x`` are not read as repository paths).
_PATH = re.compile(r"(?<![\w./-])(?:" + "|".join(CITED_DIRS) + r")/[\w*.\-/]*[\w*]")
# In the pages: backticked paths of the packages, tests and the cited dirs.
_DOC_DIRS = ("ffexp", "drivers", "tests", "layouts", "schemas", *CITED_DIRS)
_DOC_PATH = re.compile(r"`((?:" + "|".join(_DOC_DIRS) + r")/[\w*.\-/]*)`")
# In the pages: a dotted Python name of the packages at the start of an inline
# literal (`ffexp.recording.load`, `drivers.errors.FfexpError`, `ffexp.cli._common`).
_DOC_NAME = re.compile(r"`((?:ffexp|drivers)(?:\.[A-Za-z_]\w*)+)")
# A markdown link's target: [text](target).
_LINK = re.compile(r"\]\(([^)\s]+)\)")
# Fenced code blocks: not prose, not checked for names.
_FENCE = re.compile(r"^```.*?^```", flags=re.S | re.M)


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


# In docstrings and comments: a Sphinx cross-reference (``:mod:`ffexp.loop```,
# ``:class:`~drivers.base.types.RobotState```) or a double-backticked dotted name
# (````drivers.errors.FfexpError````) of the packages.
_CODE_NAME = re.compile(
    r":(?:mod|class|func|meth|attr|data|obj|exc):`~?((?:ffexp|drivers)(?:\.[A-Za-z_]\w*)+)`"
    r"|``((?:ffexp|drivers)(?:\.[A-Za-z_]\w*)+)``")


def code_cited_names(text: str) -> list[str]:
    """Dotted package names a docstring or comment cites as a cross-reference."""
    return [a or b for a, b in _CODE_NAME.findall(text)]


def test_code_name_pattern() -> None:
    text = (":mod:`ffexp.loop` and :class:`~drivers.base.types.RobotState`, "
            "``drivers.errors.FfexpError``, :func:`helper`, ``ffexp run``, `ffexp.single`")
    assert code_cited_names(text) == ["ffexp.loop", "drivers.base.types.RobotState",
                                      "drivers.errors.FfexpError"]


def test_every_cited_name_exists() -> None:
    missing = []
    for path in modules():
        for line, text in docstrings_and_comments(path.read_text(encoding="utf-8")):
            missing += [f"{path.relative_to(ROOT)}:{line}: {name}"
                        for name in code_cited_names(text) if not resolves(name)]
    assert not missing, "cited names that do not exist:\n" + "\n".join(missing)


def test_no_module_points_outside_the_repository() -> None:
    found = []
    for path in modules():
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if any(bad in line for bad in FORBIDDEN):
                found.append(f"{path.relative_to(ROOT)}:{n}: {line.strip()}")
    assert not found, "use docs/conventions.md or docs/architecture.md:\n" + "\n".join(found)


# --------------------------------------------------------------------------- the pages


# Pages the docs build writes (docs/_ext), and its output: not in git.
GENERATED = (ROOT / "docs" / "reference" / "api", ROOT / "docs" / "reference" / "cli.md",
             ROOT / "docs" / "_build")


def is_generated(path: Path) -> bool:
    path = path.resolve()
    return any(path == g or g in path.parents for g in GENERATED)


def pages() -> list[Path]:
    """Every hand-written page: the README, docs/**/*.md (not the pages the build
    writes), benchmarks/README.md."""
    docs = [p for p in sorted((ROOT / "docs").rglob("*.md")) if not is_generated(p)]
    return [ROOT / "README.md", *docs, ROOT / "benchmarks" / "README.md"]


def page_id(path: Path) -> str:
    return str(path.relative_to(ROOT))


def resolves(name: str) -> bool:
    """``name`` is an importable module, or an attribute reachable from one: a class's
    member, a dataclass or model field, or an attribute its ``__init__`` sets."""
    parts = name.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj: Any = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        for attr in parts[cut:]:
            if hasattr(obj, attr):
                obj = getattr(obj, attr)
            elif inspect.isclass(obj) and (
                attr in getattr(obj, "__annotations__", {})
                or re.search(rf"self\.{attr}\s*[:=]", inspect.getsource(obj))
            ):
                return attr == parts[-1]  # an instance attribute: nothing further to walk
            else:
                return False
        return True
    return False


def cited_names(text: str) -> list[str]:
    """Dotted package names at the start of inline literals, outside code fences."""
    return _DOC_NAME.findall(_FENCE.sub("", text))


def test_name_pattern_and_resolution() -> None:
    text = ("`ffexp.recording.load(\"x\")`, `drivers.errors.FfexpError`, `ffexp run`, "
            "`import ffexp`\n```python\nffexp.not_checked\n```\n`ffexp.no_such_module`")
    assert cited_names(text) == ["ffexp.recording.load", "drivers.errors.FfexpError",
                                 "ffexp.no_such_module"]
    assert resolves("ffexp.recording.load")
    assert resolves("drivers.errors.FfexpError")
    assert resolves("ffexp.recording.Recorder.taps")  # set in __init__
    assert not resolves("ffexp.no_such_module")
    assert not resolves("drivers.errors.NoSuchError")
    assert not resolves("ffexp.recording.Recorder.no_such_attribute")


@pytest.mark.parametrize("page", pages(), ids=page_id)
def test_pages_cite_existing_paths(page: Path) -> None:
    text = page.read_text(encoding="utf-8")
    missing = [p for p in _DOC_PATH.findall(text) if "<" not in p and not path_exists(p)]
    assert not missing, f"{page_id(page)} cites paths that do not exist: {missing}"


@pytest.mark.parametrize("page", pages(), ids=page_id)
def test_pages_name_existing_modules_and_objects(page: Path) -> None:
    names = cited_names(page.read_text(encoding="utf-8"))
    missing = [name for name in names if not resolves(name)]
    assert not missing, f"{page_id(page)} names what does not exist: {missing}"


@pytest.mark.parametrize("page", pages(), ids=page_id)
def test_pages_link_to_existing_files(page: Path) -> None:
    missing = []
    for target in _LINK.findall(page.read_text(encoding="utf-8")):
        if "://" in target or target.startswith("#"):
            continue
        path = page.parent / target.split("#", 1)[0]
        if not path.exists() and not is_generated(path):
            missing.append(target)
    assert not missing, f"{page_id(page)} links to files that do not exist: {missing}"


def test_the_docs_pages_are_found() -> None:
    found = {page_id(p) for p in pages()}
    assert {"docs/architecture.md", "docs/conventions.md", "docs/sweeps.md",
            "docs/index.md", "benchmarks/README.md"} <= found
    assert "docs/reference/cli.md" not in found


# --------------------------------------------------------------------------- the README


def readme() -> str:
    return (ROOT / "README.md").read_text(encoding="utf-8")


def test_readme_is_short() -> None:
    size = len(readme().encode("utf-8"))
    assert size <= 6 * 1024, f"README.md is {size} bytes; the rest belongs in docs/"


def test_quick_start_is_two_commands() -> None:
    text = readme()
    quick = text[text.index("## Quick start"):text.index("## Commands")]
    blocks = re.findall(r"```bash\n(.*?)```", quick, flags=re.S)
    assert blocks == [
        "python3 -m venv .venv && .venv/bin/pip install -e . && "
        ".venv/bin/ffexp campaign protocols/paper.toml\n",
        'python3 -m venv .venv && .venv/bin/pip install -e ".[test]" && .venv/bin/pytest\n',
    ]


def test_every_command_in_the_readme_table_exists() -> None:
    from typer.testing import CliRunner

    from ffexp.cli import app

    text = readme()
    table = text[text.index("| command | what it does |"):text.index("### Exit codes")]
    commands = re.findall(r"^\| `ffexp ([a-z-]+(?: [a-z0-9-]+)?)", table, flags=re.M)
    assert len(commands) >= 10
    for command in commands:
        words = command.split()
        if words[0] in ("simulate", "friction"):
            args = words[:2]
        else:
            args = words[:1]
        result = CliRunner().invoke(app, [*args, "-h"])
        assert result.exit_code == 0, (command, result.output)


@pytest.mark.parametrize("page", ["README.md", "docs/reference/exit-codes.md"])
def test_the_exit_code_table_matches_the_code(page: str) -> None:
    from ffexp.cli import _common as c

    text = (ROOT / page).read_text(encoding="utf-8")
    table = text[text.index("| code | meaning |"):]
    codes = re.findall(r"^\| (\d+|128\+N) \|", table, flags=re.M)
    assert codes == [str(c.EXIT_OK), str(c.EXIT_FAILURE), str(c.EXIT_BAD_INPUT),
                     str(c.EXIT_ABORTED), str(c.EXIT_TIMED_OUT), f"{c.EXIT_SIGNAL_BASE}+N"]
