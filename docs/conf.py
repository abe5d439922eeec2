"""Sphinx configuration of the ffexp documentation site (MyST markdown).

Build: ``sphinx-build -W --keep-going -b html docs OUT`` (as ``.ci/run`` does).
The CLI reference is written from the typer app at build time
(``docs/_ext/cli_reference.py``), the API reference from the docstrings
(autodoc, one page per package written into ``docs/reference/api/``
by ``docs/_ext/api_reference.py``).
"""

from __future__ import annotations

import re
import sys
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))  # the package of this tree, also without an install
sys.path.insert(0, str(HERE / "_ext"))

project = "ffexp"
author = "the ffexp authors"
copyright = "2026, the ffexp authors"

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "cli_reference",
    "api_reference",
]

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build", "_ext", ".gitignore"]

myst_enable_extensions = ["colon_fence", "deflist"]
myst_heading_anchors = 3
# Option names and quoted output stay as typed (no "--" turned into a dash).
smartquotes = False

# API reference (docs/_ext/api_reference.py): every module of ffexp and drivers,
# members in source order, only what the module defines (re-exports are documented
# where they live, whatever __all__ says).
autodoc_default_options = {"members": True, "member-order": "bysource",
                           "show-inheritance": True, "ignore-module-all": True}
# Only the project's own docstrings (an override of concurrent.futures.Executor.submit
# would otherwise show the standard library's text).
autodoc_inherit_docstrings = False
autodoc_typehints = "description"
autodoc_class_signature = "separated"
napoleon_google_docstring = True
napoleon_numpy_docstring = False

html_theme = "furo"
html_title = "ffexp"
html_static_path: list[str] = []


# The docstrings write absolute values as |x| (plain text); reStructuredText reads
# |x| as a substitution. Outside inline literals, a bar is escaped.
_LITERAL = re.compile(r"(``.*?``)")


def _escape_bars(_app: Any, _what: str, _name: str, _obj: Any, _options: Any,
                 lines: list[str]) -> None:
    for i, line in enumerate(lines):
        if "|" in line:
            parts = _LITERAL.split(line)
            lines[i] = "".join(p if p.startswith("``") else p.replace("|", "\\|")
                               for p in parts)


def _napoleon_except_attributes(app: Any, what: str, name: str, obj: Any, options: Any,
                                lines: list[str]) -> None:
    """Napoleon's Google sections (Args:, Returns:) for functions, classes, modules;
    an attribute's docstring is prose here, not napoleon's inline ``type: text``."""
    from sphinx.ext.napoleon import _process_docstring

    if what not in ("attribute", "property", "data"):
        _process_docstring(app, what, name, obj, options, lines)


def setup(app: Any) -> None:
    from sphinx.ext.napoleon import _process_docstring

    for listener in list(app.events.listeners.get("autodoc-process-docstring", [])):
        if listener.handler is _process_docstring:
            app.disconnect(listener.id)
    app.connect("autodoc-process-docstring", _napoleon_except_attributes)
    app.connect("autodoc-process-docstring", _escape_bars)
