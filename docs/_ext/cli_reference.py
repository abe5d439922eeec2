"""The CLI reference page, written from the typer app at build time.

:func:`render` walks the click command tree of :data:`ffexp.cli.app`
(``typer.main.get_command``) and writes every command, argument and option
with its help text as MyST markdown; :func:`setup` hooks it into Sphinx so that
``docs/reference/cli.md`` is rewritten before each build (it is not kept in git).
``tests/test_docs_site.py`` checks the page against the same tree.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

#: Where the page goes, relative to the Sphinx source directory.
PAGE = Path("reference") / "cli.md"
#: Characters that MyST (CommonMark) would read as markup in help text.
_MARKUP = re.compile(r"([\\`*_\[\]<>#|{}~])")


def commands(root: Any, name: str = "ffexp") -> Iterator[tuple[str, Any]]:
    """``(command path, click command)`` of the root and every subcommand, depth first,
    subcommands in name order."""
    yield name, root
    for sub_name, sub in sorted(getattr(root, "commands", {}).items()):
        yield from commands(sub, f"{name} {sub_name}")


def _text(help_text: str | None) -> str:
    """Help text as markdown paragraphs: click's ``\\b`` markers dropped, markup escaped."""
    if not help_text:
        return ""
    text = help_text.replace("\b\n", "").replace("\b", "")
    paragraphs = [" ".join(p.split()) for p in re.split(r"\n\s*\n", text.strip())]
    return "\n\n".join(_MARKUP.sub(r"\\\1", p) for p in paragraphs if p)


def _param(param: Any, ctx: Any) -> str:
    """One bullet: the option's names (or the argument's), its value, and the help
    text with the default as ``--help`` shows them."""
    record = param.get_help_record(ctx)
    shown, help_text = record if record else (param.display_name_raw, "")
    if param.param_type_name == "argument":
        names = f"`{param.display_name_raw}` (argument)"
    else:
        names = ", ".join(f"`{opt}`" for opt in (*param.opts, *param.secondary_opts))
    value = shown.rsplit(" ", 1)[-1] if " <" in shown or shown.endswith(">") else ""
    bullet = f"- {names}"
    if value.startswith("<"):
        bullet += f" `{value}`"
    text = _text(help_text)
    if text:
        bullet += f": {text}"
    if getattr(param, "hidden", False):
        bullet += " (hidden)"
    return bullet


def render(app: Any) -> str:
    """The whole page for the typer ``app``."""
    import typer.main

    root = typer.main.get_command(app)
    lines = [
        "# CLI reference",
        "",
        "Generated from the typer app (`ffexp.cli.app`) when the site is built: every",
        "command with its arguments and options. `-h` is `--help` everywhere. Exit codes",
        "are in [Exit codes, errors and names](exit-codes.md).",
        "",
    ]
    for path, command in commands(root):
        ctx = type(command).context_class(command, info_name=path.rsplit(" ", 1)[-1])
        lines += [f"## `{path}`", ""]
        usage = " ".join(command.collect_usage_pieces(ctx))
        lines += ["```text", f"{path} {usage}", "```", ""]
        help_text = _text(command.help)
        if help_text:
            lines += [help_text, ""]
        subs = sorted(getattr(command, "commands", {}))
        if subs:
            lines += ["Commands: " + ", ".join(f"`{path} {s}`" for s in subs) + ".", ""]
        params = command.get_params(ctx)
        if params:
            lines += [_param(p, ctx) for p in params] + [""]
    return "\n".join(lines)


def write(srcdir: Path) -> Path:
    """Write the page under ``srcdir`` (only when it changed, so builds stay incremental)."""
    from ffexp.cli import app

    page = srcdir / PAGE
    text = render(app)
    if not page.exists() or page.read_text(encoding="utf-8") != text:
        page.parent.mkdir(parents=True, exist_ok=True)
        page.write_text(text, encoding="utf-8")
    return page


def _on_builder_inited(sphinx: Any) -> None:
    write(Path(sphinx.srcdir))


def setup(sphinx: Any) -> dict[str, Any]:
    sphinx.connect("builder-inited", _on_builder_inited)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
