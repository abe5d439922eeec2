"""Which of ffexp's recordings a file is: a run's (``ffexp run``), an impact's
(``ffexp hil``) or a friction track's (``ffexp friction estimate --record``).

A command that reads a run's recording, given another kind, would fail on the
first topic or metadata it misses (``no topic /estimator/state``, ``give --scene``);
:func:`check_run_recording` names the kind instead.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ffexp.errors import InputError

#: The metadata record each kind writes first: what it is, what made it, what reads it.
OTHER_KINDS: dict[str, tuple[str, str, str]] = {
    "hil_impact": ("an impact recording", "ffexp hil", "ffexp analyze and ffexp export read it"),
    "friction": ("a friction track", "ffexp friction estimate --record",
                 "ffexp export reads it"),
}
#: The metadata record of a run's recording.
RUN_METADATA = "run"


def not_a_run(metadata: Mapping[str, Any]) -> str | None:
    """``"is a friction track (...), not a run recording (...)"`` for a recording of
    another kind; ``None`` for a run's (or a file that says nothing of itself)."""
    if RUN_METADATA in metadata:
        return None
    for key, (what, made_by, read_by) in OTHER_KINDS.items():
        if key in metadata:
            return f"is {what} ({made_by}), not a run recording ({read_by})"
    return None


def check_run(path: Path, metadata: Mapping[str, Any]) -> None:
    """Raise :class:`InputError` naming ``path`` and its kind when its ``metadata`` (a
    loaded recording's) say it is a recording of another kind than a run's."""
    what = not_a_run(metadata)
    if what is not None:
        raise InputError(f"{path}: {what}")


def check_run_recording(path: Path) -> None:
    """:func:`check_run` of the file ``path`` (reads its metadata only; a missing or
    damaged file is the one-line error of any reading)."""
    from ffexp.recording.reader import load

    check_run(path, load(path, []).metadata)
