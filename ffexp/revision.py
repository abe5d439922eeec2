"""The source revision of this ffexp: ``git describe --always --dirty`` in a git
checkout, else the package version. Every recording's ``run`` metadata and
every report carry it."""

from __future__ import annotations

import functools
import subprocess
from pathlib import Path

from ffexp import __version__

#: git gets this long to answer (a slow network file system must not stall a run).
GIT_TIMEOUT_S = 5.0


@functools.cache
def source_revision() -> str:
    """``git describe --always --dirty`` of the checkout ffexp runs from, else ``v<version>``."""
    root = Path(__file__).resolve().parents[1]
    if (root / ".git").exists():
        try:
            done = subprocess.run(
                ["git", "-C", str(root), "describe", "--always", "--dirty"],
                capture_output=True, text=True, timeout=GIT_TIMEOUT_S, check=False,
            )
        except (OSError, subprocess.TimeoutExpired):
            done = None
        if done is not None and done.returncode == 0 and done.stdout.strip():
            return done.stdout.strip()
    return f"v{__version__}"
