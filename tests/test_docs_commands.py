"""Every ``ffexp`` command the pages quote parses with the CLI as it is (an unknown option,
a missing argument or an unknown command fails here), and every example in the CLI's help
runs and is answered as bad input only where it says so."""

from __future__ import annotations

import re
import shlex
from pathlib import Path
from typing import Any

import pytest
import typer

try:  # typer 0.29 carries its own copy of click
    from typer._click.exceptions import UsageError
except ImportError:  # pragma: no cover - a typer on the installed click
    from click import UsageError

from test_docs import pages

from ffexp.cli import app

ROOT = Path(__file__).resolve().parents[1]
PAGES = pages()  # the hand-written ones (not the CLI reference the build writes)
_FENCE = re.compile(r"```[^\n]*\n(.*?)```", re.S)
_INLINE = re.compile(r"(?<!`)`(ffexp [^`]+)`(?!`)")


def quoted_commands(text: str) -> list[str]:
    """``ffexp ...`` lines of fenced blocks (continuations joined, comments and prompts
    dropped) and inline code spans that start with ``ffexp ``."""
    out: list[str] = []
    for block in _FENCE.findall(text):
        joined = re.sub(r"\s*\\\n\s*", " ", block)
        for line in joined.splitlines():
            line = re.sub(r"^\s*\$\s*", "", line).strip()
            line = re.sub(r"\s+#.*$", "", line)
            if line.startswith(".venv/bin/ffexp "):
                line = line[len(".venv/bin/"):]
            if line.startswith("ffexp "):
                out.append(line)
    out.extend(x for x in _INLINE.findall(_FENCE.sub("", text))
               if re.search(r"\S+/\S+|\.(toml|mcap)\b", x))
    return out


def parse(line: str) -> None:
    """Parse ``line`` with the CLI's own parser, invoking nothing (click's UsageError:
    an unknown command or option, a missing argument, a bad value)."""
    line = re.sub(r"\[(--[^\]]*)\]", r"\1", line)  # an optional part, shown in brackets
    words = shlex.split(line)[1:]
    cmd: Any = typer.main.get_command(app)
    ctx = cmd.make_context("ffexp", list(words), resilient_parsing=True)
    while hasattr(cmd, "resolve_command"):  # a group
        args = [*getattr(ctx, "_protected_args", []), *ctx.args]
        if not args or args[0] in ("-h", "--help"):
            return
        name, rest = args[0], args[1:]
        sub = cmd.get_command(ctx, name)
        assert sub is not None, f"no command {name!r}"
        if "-h" in rest or "--help" in rest:
            return
        cmd = sub
        ctx = sub.make_context(name or "", rest, parent=ctx)
    _check_sets(ctx)


def _check_sets(ctx: Any) -> None:
    """A quoted ``run``/``campaign``/``check`` of a protocol of the repository: its
    ``--set`` and ``--scene-set`` overrides load (the scene's included)."""
    from drivers.description.scene import load_scene
    from ffexp.cli._common import with_scene_sets
    from ffexp.protocol import load_run_protocol, scene_path

    params = ctx.params
    path = params.get("protocol")
    if ctx.info_name != "run" or path is None or not (ROOT / path).is_file():
        return
    sets = with_scene_sets(params.get("set_") or [], params.get("scene_set") or [])
    proto = load_run_protocol(ROOT / path, sets)
    load_scene(scene_path(ROOT / path, proto), proto.scene.set)


def _placeholder(line: str) -> bool:
    """A line showing a form, not a command: ``ffexp run PROTOCOL [OPTIONS]``, ``...``."""
    return "..." in line or "[" in line.split("--")[0] or "|" in line


def test_the_extractor_finds_fenced_inline_and_continued_commands() -> None:
    text = ("Run `ffexp run p.toml --set a=1` or `ffexp run`\n"
            "```bash\n$ ffexp analyze A.mcap  # one\n"
            "ffexp calibrate A.mcap \\\n    --fit target.mu --out x.toml\npython x.py\n```\n")
    assert quoted_commands(text) == ["ffexp analyze A.mcap",
                                     "ffexp calibrate A.mcap --fit target.mu --out x.toml",
                                     "ffexp run p.toml --set a=1"]


def test_the_parser_refuses_an_unknown_option_and_command() -> None:
    with pytest.raises(UsageError):
        parse("ffexp run p.toml --no-such-option")
    with pytest.raises(AssertionError):
        parse("ffexp no-such-command x")


CASES = [(page, line) for page in PAGES
         for line in dict.fromkeys(quoted_commands(page.read_text(encoding="utf-8")))
         if not _placeholder(line)]


def test_the_pages_quote_many_commands() -> None:
    assert len(CASES) >= 30


@pytest.mark.parametrize(("page", "line"), CASES,
                         ids=[f"{p.relative_to(ROOT)}: {x}" for p, x in CASES])
def test_every_quoted_command_parses(page: Path, line: str) -> None:
    try:
        parse(line)
    except UsageError as exc:
        pytest.fail(f"{page.relative_to(ROOT)}: `{line}`: {exc.format_message()}")


# -- the CLI's help examples ------------------------------------------------------------
# Here each option-value example loads through the loader its command uses (quick, and the
# Example: lines run); tests/test_help_examples.py runs each with its command.
_EXAMPLE = re.compile(r"(--set|--scene-set|--rig-set|--fit) ([^\s()]+)")
_COMMAND = re.compile(r"Example: (ffexp [^\n]+)")


def _commands(cmd: Any, path: tuple[str, ...] = ()) -> list[tuple[tuple[str, ...], Any]]:
    if hasattr(cmd, "commands"):
        return [x for name, sub in cmd.commands.items() for x in _commands(sub, (*path, name))]
    return [(path, cmd)]


def help_examples() -> list[tuple[str, str, str]]:
    """``(command, option, value)`` of every ``--set``/``--scene-set``/``--rig-set``/``--fit``
    example in an option's help, and ``(command, "", line)`` of every ``Example:`` line."""
    out = []
    for path, cmd in _commands(typer.main.get_command(app)):
        name = " ".join(path)
        for p in cmd.params:
            for opt, value in _EXAMPLE.findall(getattr(p, "help", "") or ""):
                out.append((name, opt, value.rstrip(".,;")))
        out.extend((name, "", line) for line in _COMMAND.findall(cmd.help or ""))
    return sorted(set(out))


def _check_example(command: str, option: str, value: str) -> None:
    from typer.testing import CliRunner

    from drivers.config import load_model
    from drivers.description.scene import load_scene
    from ffexp.calibrate.params import parse_fit
    from ffexp.calibrate.resim import base_scene
    from ffexp.cli._common import with_scene_sets
    from ffexp.contact1dof.sweep import SweepProtocol
    from ffexp.experiment import load_rig_choice
    from ffexp.protocol import load_run_protocol, scene_path
    from ffexp.rig_choice import RigChoice

    protocol = ROOT / "protocols/method1_case1.toml"
    scene = ROOT / "data/scenes/paper.toml"
    if not option:  # a whole command line: it runs (these write nothing)
        result = CliRunner().invoke(app, shlex.split(value)[1:])
        assert result.exit_code == 0, result.stderr
    elif command == "simulate sweep":
        load_model(SweepProtocol, ROOT / "protocols/sec3_damping.toml", [value])
    elif command in ("hil", "hil-sweep"):  # the impact protocol's own keys
        from ffexp.hil.protocol import load_hil_protocol, split_sets

        proto_sets, scene_sets = split_sets([value] if option == "--set" else [],
                                            [value] if option == "--scene-set" else [])
        hil = load_hil_protocol(ROOT / "protocols/hil_impact.toml", proto_sets)
        load_scene(hil.scene, scene_sets)
    elif option == "--fit":
        parse_fit([value], base_scene(scene))
    elif option == "--rig-set":
        load_rig_choice(RigChoice(driver="fri", overrides=("robot.robot_ip='10.0.0.1'", value)))
    elif command in ("calibrate", "resimulate", "emulate") and option != "--fit":
        load_scene(scene, [value])  # their --set / --scene-set override the scene itself
    else:  # a run protocol's --set or --scene-set
        sets = with_scene_sets([value] if option == "--set" else [],
                               [value] if option == "--scene-set" else [])
        proto = load_run_protocol(protocol, sets)
        load_scene(scene_path(protocol, proto), proto.scene.set)


EXAMPLES = help_examples()


def test_the_help_has_examples_of_every_override_option() -> None:
    options = {o for _c, o, _v in EXAMPLES}
    assert {"--set", "--scene-set", "--rig-set", "--fit", ""} <= options
    assert ("run", "--set", "scene.target.lateral=0.012") in EXAMPLES


@pytest.mark.parametrize(("command", "option", "value"), EXAMPLES,
                         ids=[f"{c} {o} {v}" for c, o, v in EXAMPLES])
def test_every_help_example_works(command: str, option: str, value: str) -> None:
    _check_example(command, option, value)


@pytest.mark.parametrize("form", ["align.f_ref=[0,0,1.2,0,0,0]", "run.timeout_s=20",
                                  "align.k_ri[3]=1.0", "scene.target.lateral=0.012"])
def test_the_override_forms_the_simulation_guide_quotes_work(form: str) -> None:
    guide = (ROOT / "docs/guides/simulation.md").read_text(encoding="utf-8")
    assert form.split("=")[0] in guide
    _check_example("run", "--set", form)


# -- results pages: dated, and the guides link the latest ---------------------------------
RESULTS = ROOT / "docs/results"
_DATE = re.compile(r"^(\d{4}-\d{2}-\d{2})")
_LINK = re.compile(r"\]\(([^)#\s]+)(?:#[^)]*)?\)")


def superseded(page: Path) -> bool:
    """A results page that says a later page replaced it (in its first lines)."""
    return "Superseded by" in "\n".join(page.read_text(encoding="utf-8").splitlines()[:6])


def test_every_results_page_is_dated_in_its_name_and_its_title() -> None:
    pages = sorted(RESULTS.glob("*.md"))
    assert pages
    for page in pages:
        m = _DATE.match(page.name)
        assert m, f"{page.name}: a results page's name starts with its date"
        title = page.read_text(encoding="utf-8").splitlines()[0]
        assert title.startswith("# ") and m.group(1) in title, (page.name, title)


@pytest.mark.parametrize("page", [p for p in PAGES if RESULTS not in p.parents],
                         ids=lambda p: str(p.relative_to(ROOT)))
def test_pages_link_no_superseded_results(page: Path) -> None:
    old = [t for t in _LINK.findall(page.read_text(encoding="utf-8"))
           if "results/" in t and (page.parent / t).is_file() and superseded(page.parent / t)]
    assert not old, f"{page.relative_to(ROOT)} links superseded results pages: {old}"


def test_a_superseded_page_is_found() -> None:
    assert superseded(RESULTS / "2026-11-26.md")
    assert not superseded(RESULTS / "2026-11-26-fidelity.md")
