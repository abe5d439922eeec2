"""The API reference pages, written from the package tree at build time.

One page per package of ``ffexp`` and ``drivers`` (``docs/reference/api/``, not
kept in git): the package's docstring, then every plain module of it with
``automodule`` (members from the docstrings), then a table of contents of its
subpackages. One page per package rather than per module keeps the site small
and the build fast; the module sections are the page's own contents.
"""

from __future__ import annotations

import pkgutil
from collections.abc import Iterator
from importlib import import_module
from pathlib import Path
from typing import Any

#: Where the pages go, relative to the Sphinx source directory.
OUT = Path("reference") / "api"
#: The top-level packages documented.
PACKAGES = ("drivers", "ffexp")
#: Modules not documented: ``python -m ffexp`` runs the CLI when imported.
SKIP = frozenset({"ffexp.__main__"})


def packages(name: str) -> Iterator[tuple[str, list[str], list[str]]]:
    """``(package, its plain modules, its subpackages)`` for ``name`` and every
    subpackage below it, depth first, in name order."""
    package = import_module(name)
    plain: list[str] = []
    subs: list[str] = []
    for info in sorted(pkgutil.iter_modules(package.__path__), key=lambda i: i.name):
        full = f"{name}.{info.name}"
        if full in SKIP:
            continue
        (subs if info.ispkg else plain).append(full)
    yield name, plain, subs
    for sub in subs:
        yield from packages(sub)


def _title(text: str, char: str) -> list[str]:
    return [text, char * len(text), ""]


def page(name: str, plain: list[str], subs: list[str]) -> str:
    """The reStructuredText of one package's page."""
    lines = _title(name, "=")
    lines += [f".. automodule:: {name}", ""]
    if subs:
        lines += [".. toctree::", "   :maxdepth: 1", "   :caption: Subpackages", ""]
        lines += [f"   {sub}" for sub in subs] + [""]
    for module in plain:
        lines += _title(module, "-")
        lines += [f".. automodule:: {module}", ""]
    return "\n".join(lines)


def write(srcdir: Path) -> list[Path]:
    """Write every page under ``srcdir`` (only those that changed) and remove pages of
    packages that are gone."""
    out = srcdir / OUT
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for top in PACKAGES:
        for name, plain, subs in packages(top):
            path = out / f"{name}.rst"
            text = page(name, plain, subs)
            if not path.exists() or path.read_text(encoding="utf-8") != text:
                path.write_text(text, encoding="utf-8")
            written.append(path)
    for stale in set(out.glob("*.rst")) - set(written):
        stale.unlink()
    return written


def _on_builder_inited(sphinx: Any) -> None:
    write(Path(sphinx.srcdir))


def setup(sphinx: Any) -> dict[str, Any]:
    sphinx.connect("builder-inited", _on_builder_inited)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
