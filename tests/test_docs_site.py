"""The generated parts of the documentation site, and what the live-view guide promises.

The CLI reference (``docs/_ext/cli_reference.py``) must list every command of
the typer app with every one of its options and arguments, checked here
against the click command tree walked independently; the API reference
(``docs/_ext/api_reference.py``) must cover every module of ``ffexp`` and
``drivers``; and the WebSocket subprotocols that ``docs/guides/recordings.md``
names as accepted (and refused) must be what the installed foxglove-sdk
server accepts. The site itself is built by ``.ci/run`` with warnings as
errors.
"""

from __future__ import annotations

import asyncio
import importlib.util
import re
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXT = ROOT / "docs" / "_ext"


def extension(name: str) -> ModuleType:
    """A module of docs/_ext, loaded from its file."""
    spec = importlib.util.spec_from_file_location(f"docs_ext_{name}", EXT / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


# --------------------------------------------------------------------------- the CLI reference


def expected_commands() -> dict[str, set[str]]:
    """Command path -> every option name (``--x``, ``-x``, ``--no-x``) and argument
    name, from the typer app's click tree (help options included)."""
    import typer.main

    from ffexp.cli import app

    out: dict[str, set[str]] = {}

    def walk(command: Any, path: str) -> None:
        ctx = type(command).context_class(command, info_name=path.rsplit(" ", 1)[-1])
        names: set[str] = set()
        for param in command.get_params(ctx):
            if param.param_type_name == "argument":
                names.add(param.name)
            else:
                names.update(param.opts)
                names.update(param.secondary_opts)
        out[path] = names
        for name, sub in getattr(command, "commands", {}).items():
            walk(sub, f"{path} {name}")

    walk(typer.main.get_command(app), "ffexp")
    return out


def listed_commands(page: str) -> dict[str, set[str]]:
    """Command path -> the option and argument names the page lists under it."""
    out: dict[str, set[str]] = {}
    for section in re.split(r"^## ", page, flags=re.M)[1:]:
        heading, _, body = section.partition("\n")
        path = heading.strip().strip("`")
        names: set[str] = set()
        for bullet in re.findall(r"^- (.*)$", body, flags=re.M):
            head = bullet.split(":", 1)[0]
            names.update(re.findall(r"`(-[\w-]+)`", head))
            argument = re.match(r"`(\w+)` \(argument\)", head)
            if argument:
                names.add(argument.group(1))
        out[path] = names
    return out


def missing_from(page: str) -> list[str]:
    """What the click tree has and the page does not list."""
    listed = listed_commands(page)
    missing = []
    for path, names in expected_commands().items():
        if path not in listed:
            missing.append(path)
            continue
        missing += [f"{path} {name}" for name in sorted(names - listed[path])]
    return missing


@pytest.fixture(scope="module")
def cli_page() -> str:
    from ffexp.cli import app

    return str(extension("cli_reference").render(app))


def test_the_cli_reference_lists_every_command_and_option(cli_page: str) -> None:
    expected = expected_commands()
    assert len(expected) >= 20 and "ffexp run" in expected
    assert "--camera-calibration" in expected["ffexp emulate"]
    assert missing_from(cli_page) == []
    assert set(listed_commands(cli_page)) == set(expected)


def test_the_check_notices_a_missing_option_and_command(cli_page: str) -> None:
    without_option = re.sub(r"^- `--live-address`.*\n", "", cli_page, flags=re.M)
    assert missing_from(without_option) == ["ffexp run --live-address"]
    without_command = cli_page.replace("## `ffexp topics`", "## `ffexp topix`")
    assert "ffexp topics" in missing_from(without_command)


def test_help_text_markup_is_escaped() -> None:
    text = extension("cli_reference")._text("Set |a-b| *x* <y> [z]\n\n\b\nnext   line")
    assert text == "Set \\|a-b\\| \\*x\\* \\<y\\> \\[z\\]\n\nnext line"


def test_the_cli_page_is_written_only_when_it_changed(tmp_path: Path) -> None:
    cli = extension("cli_reference")
    page = cli.write(tmp_path)
    assert page == tmp_path / "reference" / "cli.md"
    page.write_text("old", encoding="utf-8")
    cli.write(tmp_path)
    assert page.read_text(encoding="utf-8").startswith("# CLI reference")
    mtime = page.stat().st_mtime_ns
    cli.write(tmp_path)
    assert page.stat().st_mtime_ns == mtime


# --------------------------------------------------------------------------- the API reference


def test_the_api_reference_covers_every_module(tmp_path: Path) -> None:
    api = extension("api_reference")
    documented: set[str] = set()
    for package, plain, subs in (entry for top in api.PACKAGES for entry in api.packages(top)):
        documented.add(package)
        documented.update(plain)
        assert all(sub.startswith(package + ".") for sub in subs)
    on_disk = set()
    for top in api.PACKAGES:
        for path in (ROOT / top).rglob("*.py"):
            parts = path.relative_to(ROOT).with_suffix("").parts
            on_disk.add(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    assert documented == on_disk - api.SKIP
    written = api.write(tmp_path)
    packages = {name for name in on_disk if (ROOT / name.replace(".", "/")).is_dir()}
    assert {p.stem for p in written} == packages
    ffexp_page = (tmp_path / "reference" / "api" / "ffexp.rst").read_text(encoding="utf-8")
    assert ".. automodule:: ffexp.loop" in ffexp_page and "   ffexp.recording" in ffexp_page
    assert "ffexp.__main__" not in ffexp_page


# --------------------------------------------------------------------------- live view


def subprotocols_in_guide() -> tuple[list[str], list[str]]:
    """(accepted, refused) subprotocols as docs/guides/recordings.md names them."""
    text = (ROOT / "docs" / "guides" / "recordings.md").read_text(encoding="utf-8")
    paragraph = text[text.index("**WebSocket subprotocols.**"):]
    paragraph = paragraph[:paragraph.index("\n\n")]
    accepted_part, _, refused_part = paragraph.partition("is refused")
    accepted = re.findall(r"`(foxglove\.[\w.]+)`", accepted_part.split("A client that")[0])
    refused = re.findall(r"`(foxglove\.[\w.]+)`", accepted_part.split("A client that")[1])
    assert refused_part, "the guide says which subprotocols are refused"
    return accepted, refused


async def _answer(url: str, subprotocol: str) -> str:
    import websockets

    try:
        async with websockets.connect(url, subprotocols=[subprotocol],  # type: ignore[list-item]
                                      close_timeout=0.5, open_timeout=5) as ws:
            return str(ws.subprotocol)
    except websockets.exceptions.InvalidStatus as exc:
        return f"refused {exc.response.status_code}"


def test_the_guide_names_the_subprotocols_the_server_accepts() -> None:
    pytest.importorskip("websockets")
    import foxglove

    accepted, refused = subprotocols_in_guide()
    assert "foxglove.sdk.v1" in accepted and refused == ["foxglove.websocket.v1"]
    server = foxglove.start_server(name="docs-test", host="127.0.0.1", port=0,
                                   context=foxglove.Context())
    try:
        url = f"ws://127.0.0.1:{server.port}"
        for name in accepted:
            assert asyncio.run(_answer(url, name)) == name
        for name in refused:
            assert asyncio.run(_answer(url, name)) == "refused 400"
    finally:
        server.stop()
