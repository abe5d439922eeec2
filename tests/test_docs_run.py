"""Every ``ffexp`` command the README and the guides quote runs on a fresh checkout and ends
as the page says (exit 0, or the ``# exit N`` its comment gives), page by page in the order a
reader types them, each page in its own directory beside the repository's files.

What runs, by rule (no list of commands here):

- **Placeholders** take what the test makes: an upper-case ``NAME.mcap`` (``RUN.mcap``,
  ``runs/X.mcap``) read by a command is a recording of ``protocols/method1_case1.toml``; an
  upper-case ``NAME.csv`` is a camera's reference points; ``<time>`` is whatever the page's
  earlier command wrote there; a bare upper-case value (``--fit KEY``) is the example the
  CLI's help gives for that option; a loop's ``$m`` is the loop's first value. Absolute
  output paths (``/tmp/kyp.mcap``) land inside the page's directory.
- **Hardware** is parsed only (``tests/test_docs_commands.py``), never run: a command whose
  rig (``--rig``, ``--driver``, ``--robot-ip``) has a robot with no simulated scene (a KRC, a
  UR controller: the real one or ``ffexp emulate`` in another terminal), ``ffexp emulate``
  itself (it serves such a controller to a run in another terminal), ``--executor ray...``
  (a Ray cluster), and a command that reads what one of those writes on the same page.
- **A long study has a short twin**: an HTML comment ``<!-- twin: ffexp ... -->`` on a page
  (invisible on the site) stands for every quoted command of the same subcommand and
  positional arguments (on that page first, else on any page): the twin names at least
  the options the long form names, and runs instead with fewer points, seeds or seconds.
- **Results pages** (``docs/results/``) are dated records of a study that took its own
  hours: their commands run as their twins (a results page's own, else a guide's), so a
  reader who repeats a study finds its commands still work.
- A live server (``--live``) listens on a free loopback port instead of Foxglove's 8765,
  and a viewer comes after the run and leaves, as the reader in Foxglove would; the
  server then stops by itself (it serves until its viewer has left).
"""

from __future__ import annotations

import re
import shlex
import shutil
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import pytest
import typer
from test_docs import pages
from test_docs_commands import help_examples, parse
from typer.testing import CliRunner

from ffexp.cli import app

ROOT = Path(__file__).resolve().parents[1]
BESIDE = ("protocols", "data", "rigs", "schemas", "layouts", "tests")  # what they read
_BLOCK = re.compile(r"```[^\n]*\n(.*?)```", re.S)
_INLINE = re.compile(r"(?<!`)`(ffexp [^`]+)`(?!`)")
_TWIN = re.compile(r"^<!--\s*twin:\s*(ffexp .*?)\s*-->", re.S | re.M)  # at a line start
_EXIT = re.compile(r"#.*?\bexit (\d+)")
_LOOP = re.compile(r"^\s*for (\w+) in (\S+)[^;]*; do\s*$")
_RECORDING = re.compile(r"(?:^|/)(?:[A-Z][A-Z0-9_]*)\.mcap$")
_POINTS = re.compile(r"(?:^|/)(?:[A-Z][A-Z0-9_]*)\.csv$")
_VALUE = re.compile(r"^[A-Z][A-Z0-9_]*$")
_OUT = ("--out", "-o")


@dataclass(frozen=True)
class Quoted:
    """One command of a page: as the page quotes it, and the exit code it promises."""

    line: str
    exit_code: int = 0


def quoted(text: str) -> list[Quoted]:
    """The page's ``ffexp`` commands in page order: fenced lines (continuations joined,
    prompts dropped, a loop's variable at its first value) and inline spans that name a
    file; ``# exit N`` in a line's comment is its exit code."""
    found: list[tuple[int, Quoted]] = []
    for m in _BLOCK.finditer(text):
        joined = re.sub(r"\s*\\\n\s*", " ", m.group(1))
        var: dict[str, str] = {}
        for line in joined.splitlines():
            loop = _LOOP.match(line)
            if loop:
                var = {loop.group(1): loop.group(2)}
                continue
            if line.strip() == "done":
                var = {}
                continue
            code = _EXIT.search(line)
            line = re.sub(r"\s+#.*$", "", re.sub(r"^\s*\$\s*", "", line)).strip()
            line = line.removeprefix(".venv/bin/")
            for name, value in var.items():
                line = line.replace(f"${name}", value)
            if line.startswith("ffexp "):
                found.append((m.start(), Quoted(line, int(code.group(1)) if code else 0)))
    blanked = _BLOCK.sub(lambda m: " " * len(m.group(0)), text)
    for m in _INLINE.finditer(blanked):
        line = " ".join(m.group(1).split())
        if re.search(r"\S+/\S+|\.(toml|mcap|csv)\b", line):
            found.append((m.start(), Quoted(line)))
    return [q for _pos, q in sorted(found, key=lambda x: x[0])]


def _placeholder(line: str) -> bool:
    """A form, not a command: ``ffexp run PROTOCOL [OPTIONS]``, ``...``, ``a|b``."""
    return "..." in line or "[" in line.split("--")[0] or "|" in line


def _words(line: str) -> list[str]:
    line = re.sub(r"\[(--[^\]]*)\]", r"\1", line)  # an optional part, shown in brackets
    return shlex.split(line)[1:]


@cache
def _cli() -> Any:
    return typer.main.get_command(app)


@cache
def _examples() -> dict[tuple[str, str], str]:
    return {(c, o): v for c, o, v in help_examples() if o}


def _command(words: list[str]) -> tuple[tuple[str, ...], dict[str, Any], list[str]]:
    """(command path, parsed parameters, option names given) of ``ffexp WORDS``."""
    cmd: Any = _cli()
    ctx = cmd.make_context("ffexp", list(words), resilient_parsing=True)
    path: list[str] = []
    while hasattr(cmd, "resolve_command"):
        args = [*getattr(ctx, "_protected_args", []), *ctx.args]
        name, rest = args[0], args[1:]
        cmd = cmd.get_command(ctx, name)
        path.append(name)
        ctx = cmd.make_context(name, rest, parent=ctx, resilient_parsing=True)
    names = [w.split("=")[0] for w in words if w.startswith("-")]
    return tuple(path), dict(ctx.params), names


def _key(words: list[str]) -> tuple[str, ...]:
    """What a twin stands for: the command path and its first positional argument (the
    protocol, campaign or first recording; a twin may take fewer recordings)."""
    path, params, _ = _command(words)
    cmd: Any = _cli()
    for name in path:
        cmd = cmd.commands[name]
    for p in cmd.params:
        value = params.get(p.name)
        if p.param_type_name == "argument" and value is not None:
            first = value[0] if isinstance(value, list | tuple) else value
            return (*path, str(first))
    return tuple(path)


# -- which commands need hardware (a rule on the parsed command) ------------------------
def needs_hardware(words: list[str]) -> str | None:
    """Why this command cannot run on a fresh checkout alone, or ``None``."""
    from drivers import registry
    from ffexp.cli.run import rig_choice
    from ffexp.experiment import load_rig_choice

    path, params, _ = _command(words)
    if path == ("emulate",):
        return "it serves a robot controller to a run in another terminal"
    if str(params.get("executor") or "").startswith("ray"):
        return "a Ray cluster"
    if not any(params.get(k) for k in ("rig", "driver", "robot_ip")):
        return None
    sets = list(params.get("rig_set") or [])
    if params.get("robot_ip"):
        sets.append(f"robot.robot_ip={params['robot_ip']!r}")
    rig = params.get("rig")
    choice = rig_choice(ROOT / rig if rig else None, params.get("driver"), sets)
    rig, _source = load_rig_choice(choice)
    kind = rig.robot.type
    if registry.robot_backend(kind).scene is None and kind != "mock":
        return f"a robot ({kind}: the controller, or its emulator in another terminal)"
    return None


# -- the twins ----------------------------------------------------------------------------
PAGES = list(pages())


def twins(page: Path) -> dict[tuple[str, ...], str]:
    return {_key(_words(t)): t for t in _TWIN.findall(page.read_text(encoding="utf-8"))}


ALL_TWINS = {k: t for p in PAGES for k, t in twins(p).items()}


@cache
def planned(page: Path) -> list[tuple[Quoted, str, str | None]]:
    """(quoted command, the line that runs, why it is not run or ``None``) in page order."""
    own = twins(page)
    out: list[tuple[Quoted, str, str | None]] = []
    skipped_outs: list[str] = []
    for q in quoted(page.read_text(encoding="utf-8")):
        if _placeholder(q.line):
            continue
        words = _words(q.line)
        why = needs_hardware(words)
        if why is None and any(w.startswith(o) for w in words for o in skipped_outs):
            why = "it reads what a command needing hardware on this page writes"
        if why is not None:
            skipped_outs += [words[i + 1].rstrip("/") for i, w in enumerate(words[:-1])
                             if w in _OUT]
            out.append((q, q.line, why))
            continue
        key = _key(words)
        out.append((q, own.get(key) or ALL_TWINS.get(key) or q.line, None))
    return out


# -- making what the placeholders stand for -----------------------------------------------
@pytest.fixture(scope="session")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("recording")
    result = CliRunner().invoke(app, ["run", str(ROOT / "protocols/method1_case1.toml"),
                                      "--out", str(out)])
    assert result.exit_code == 0, result.output
    (path,) = out.glob("*.mcap")
    return path


def _points(path: Path) -> None:
    """Reference points of a camera 1000 px per m over the table, origin at (320, 240)."""
    rows = [(x, y) for x in (-0.1, 0.0, 0.1) for y in (-0.1, 0.1)]
    path.write_text("u,v,x,y\n" + "".join(f"{320 + 1000 * x:g},{240 - 1000 * y:g},{x},{y}\n"
                                          for x, y in rows))


def resolve(words: list[str], cwd: Path, recording: Path) -> list[str]:
    """The placeholders of ``words`` made real in ``cwd`` (see the module's text)."""
    path, _params, _ = _command(words)
    examples = _examples()
    out: list[str] = []
    for i, w in enumerate(words):
        after_out = i > 0 and words[i - 1] in _OUT
        if after_out and w.startswith("/"):
            w = str(cwd / w.lstrip("/"))
            Path(w).parent.mkdir(parents=True, exist_ok=True)
        elif "<" in w and ">" in w:
            matches = sorted(cwd.glob(re.sub(r"<[^>]+>", "*", w)))
            assert len(matches) == 1, f"{w}: {matches}"
            w = str(matches[0].relative_to(cwd))
        elif not after_out and _RECORDING.search(w) and not (cwd / w).exists():
            (cwd / w).parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(recording, cwd / w)
        elif not after_out and _POINTS.search(w) and not (cwd / w).exists():
            _points(cwd / w)
        elif i > 0 and words[i - 1].startswith("-") and _VALUE.match(w):
            w = examples[(" ".join(path), words[i - 1])]
        out.append(w)
    return out


def _directory(tmp_path: Path) -> Path:
    for name in BESIDE:
        if (ROOT / name).exists():
            (tmp_path / name).symlink_to(ROOT / name)
    return tmp_path


def _a_viewer_comes_after_the_run(monkeypatch: pytest.MonkeyPatch) -> None:
    """``--live`` serves the ended run until its viewer has left: the reader opens Foxglove
    once the run is over, looks and closes it (a WebSocket client that subscribes and
    leaves); the server then stops by itself."""
    import asyncio
    import threading

    from test_live_linger import _visit

    from ffexp.live.server import LiveServer

    original = LiveServer.linger

    def linger(self: LiveServer, flag: Any) -> str:
        threading.Thread(target=lambda: asyncio.run(_visit(self.url)), daemon=True).start()
        return original(self, flag)

    monkeypatch.setattr(LiveServer, "linger", linger)


def run_page(page: Path, cwd: Path, recording: Path, monkeypatch: pytest.MonkeyPatch) -> int:
    """Run the page's commands in ``cwd``; how many ran."""
    import ffexp.live.address

    monkeypatch.chdir(cwd)
    monkeypatch.setattr(ffexp.live.address, "DEFAULT_ADDRESS", "127.0.0.1:0")
    _a_viewer_comes_after_the_run(monkeypatch)
    ran = 0
    for q, line, why in planned(page):
        if why is not None:
            continue
        words = resolve(_words(line), cwd, recording)
        result = CliRunner().invoke(app, words)
        assert result.exit_code == q.exit_code, (
            f"{page.relative_to(ROOT)}: `{q.line}`"
            + (f" (run as its twin `{line}`)" if line != q.line else "")
            + f": exit {result.exit_code}, the page says {q.exit_code}\n"
            + result.output[-3000:])
        ran += 1
    return ran


RUN = [p for p in PAGES if any(why is None for _q, _l, why in planned(p))]


@pytest.mark.slow
@pytest.mark.parametrize("page", RUN, ids=[str(p.relative_to(ROOT)) for p in RUN])
def test_every_command_a_page_quotes_runs_as_the_page_says(
        page: Path, tmp_path: Path, recording: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    assert run_page(page, _directory(tmp_path), recording, monkeypatch) > 0


# -- the rules themselves -----------------------------------------------------------------
def test_the_pages_run_most_of_what_they_quote() -> None:
    plans = [x for p in PAGES for x in planned(p)]
    ran = [q for q, _l, why in plans if why is None]
    assert len(ran) >= 25 and 3 * len(ran) >= 2 * len(plans)


@pytest.mark.parametrize(("line", "why"), [
    ("ffexp run protocols/method1_case1.toml", None),
    ("ffexp run protocols/method1_case1.toml --rig rigs/mock.toml", None),
    ("ffexp run protocols/method1_case1.toml --rig rigs/ur5e-sim.toml", None),
    ("ffexp run protocols/method1_case1.toml --rig rigs/emulator.toml", "a robot (fri1"),
    ("ffexp run protocols/method1_case1.toml --driver ur --robot-ip 10.0.0.2", "a robot (ur"),
    ("ffexp emulate --robot ur5e --duration 1", "serves a robot controller"),
    ("ffexp reproduce --executor ray:auto", "a Ray cluster"),
])
def test_hardware_is_told_by_the_rig_not_by_a_list(line: str, why: str | None) -> None:
    got = needs_hardware(_words(line))
    assert (got is None) if why is None else (got is not None and why in got), got


def test_a_twin_names_every_option_of_the_long_form_it_stands_for() -> None:
    for page in PAGES:
        for q, line, why in planned(page):
            if why is None and line != q.line:
                long_names = set(_command(_words(q.line))[2])
                twin_names = set(_command(_words(line))[2])
                assert long_names <= twin_names, (page.name, q.line, line)
                parse(line)


def test_every_twin_stands_for_a_command_its_page_quotes() -> None:
    for page in PAGES:
        used = {line for _q, line, why in planned(page) if why is None}
        for key, twin in twins(page).items():
            assert twin in used, f"{page.name}: the twin `{twin}` stands for nothing ({key})"


def test_the_extractor_keeps_page_order_loops_and_exit_codes() -> None:
    text = ("Run `ffexp run p.toml --set a=1` first.\n```bash\nfor m in a b; do\n"
            "  ffexp sweep protocols/x_$m.toml \\\n    --out s/$m\ndone\n"
            "ffexp diff A.mcap B.mcap   # exit 1: they differ\n```\n"
            "<!-- twin: ffexp diff A.mcap B.mcap --atol 1 -->\n")
    assert quoted(text) == [Quoted("ffexp run p.toml --set a=1"),
                            Quoted("ffexp sweep protocols/x_a.toml --out s/a"),
                            Quoted("ffexp diff A.mcap B.mcap", 1)]
    assert _TWIN.findall(text) == ["ffexp diff A.mcap B.mcap --atol 1"]


def test_placeholders_are_made_in_the_page_directory(tmp_path: Path) -> None:
    rec = tmp_path / "r.mcap"
    rec.write_bytes(b"x")
    (tmp_path / "runs" / "paper-20260101-000000").mkdir(parents=True)
    words = resolve(_words("ffexp calibrate RUN.mcap --fit KEY --out /tmp/x/SCENE.toml"),
                    tmp_path, rec)
    assert words == ["calibrate", "RUN.mcap", "--fit", "target.mu=0.002:0.01",
                     "--out", str(tmp_path / "tmp/x/SCENE.toml")]
    assert (tmp_path / "RUN.mcap").read_bytes() == b"x"
    assert resolve(_words("ffexp report runs/paper-<time>"), tmp_path, rec) == \
        ["report", "runs/paper-20260101-000000"]
    resolve(_words("ffexp calibrate-camera POINTS.csv OUT.toml"), tmp_path, rec)
    assert (tmp_path / "POINTS.csv").read_text().startswith("u,v,x,y\n")
