"""ffexp: force-control experiments on free-floating objects.

See README.md for the quick start, docs/architecture.md for the architecture and
docs/conventions.md for frames, signs and units. Importing the package imports
nothing else (the command line starts fast); the modules import what they need.
``ffexp.recording`` is loaded on first use, so that after ``import ffexp`` a
notebook can call ``ffexp.recording.load(path).frame("/estimator/state")``.
"""

from __future__ import annotations

import importlib
from types import ModuleType

__version__ = "0.1.0"

#: Subpackages loaded on first attribute access (PEP 562), not at ``import ffexp``.
_LAZY = ("recording",)


def __getattr__(name: str) -> ModuleType:
    if name in _LAZY:
        return importlib.import_module(f"ffexp.{name}")
    raise AttributeError(f"module 'ffexp' has no attribute {name!r}")
