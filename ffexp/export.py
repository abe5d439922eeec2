"""Tables out of a recording (``ffexp export``): one file per topic, Parquet or CSV.

Each table is the topic's frame (:mod:`ffexp.recording.frames`): ``t_s`` (seconds
from the run start), ``log_time_ns``, then one column per field, array fields
split into ``name_0 .. name_k``. Files are named after the topic, slashes turned
into underscores (``/estimator/state`` -> ``estimator_state.parquet``); an
existing table of the same name is replaced. CSV is written with every digit
(Python's shortest round-trip form), so ``pandas.read_csv`` (pandas 3: round-trip
float parsing by default) reads back the exact values.

Beside the tables, ``recording.json`` says what the tables come from: the file,
the run, whether the recording holds the run's end (``complete``) and the
trial's validity (``unknown: the run ended abnormally`` when it does not), and
the reader's warnings.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ffexp.errors import ConfigError, InputError
from ffexp.recording import Recording

FORMATS = ("parquet", "csv")
#: The file beside the tables that says whether the run's end is in them.
SUMMARY_FILE = "recording.json"
#: What :func:`summary` reads besides the exported topics.
SUMMARY_TOPICS = ("/runner/phase", "/robot/state", "/estimator/state", "/robot/link",
                  "/robot/link_driver", "/events")


def summary(rec: Recording) -> dict[str, Any]:
    """The recording's file, run, completeness and trial validity (``recording.json``)."""
    from ffexp.analysis import run_name
    from ffexp.linkcheck import check_link

    link = check_link(rec)
    return {"file": str(rec.path), "run": run_name(rec), "complete": rec.complete,
            "trial_valid": link.trial_valid, "trial_validity": link.validity,
            "warnings": list(rec.warnings)}


def table_name(topic: str) -> str:
    """``/estimator/state`` -> ``estimator_state``."""
    return topic.strip("/").replace("/", "_") or "root"


def default_dir(path: Path) -> Path:
    """Where ``ffexp export`` writes without ``--out``: ``<run>-tables`` beside the file."""
    return path.with_name(f"{path.stem}-tables")


def export(rec: Recording, fmt: str, out_dir: Path, topics: Sequence[str] = ()) -> list[Path]:
    """Write one table per topic (``topics``, or every topic of ``rec``) and
    :data:`SUMMARY_FILE`; the paths."""
    if fmt not in FORMATS:
        raise ConfigError("--format", fmt, f"choose one of {', '.join(FORMATS)}")
    names = list(topics) or [*rec.topics, *rec.json]
    frames = {t: rec.frame(t) for t in names}  # a topic it lacks fails before any write
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError(f"{out_dir}: exists and is not a directory (--out)")
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{out_dir}: cannot create: {exc.strerror}") from None
    written = []
    for topic, df in frames.items():
        path = out_dir / f"{table_name(topic)}.{fmt}"
        try:
            if fmt == "parquet":
                df.to_parquet(path, index=False)
            else:
                df.to_csv(path, index=False)
        except OSError as exc:
            raise InputError(f"{path}: cannot write: {exc.strerror}") from None
        written.append(path)
    path = out_dir / SUMMARY_FILE
    try:
        path.write_text(json.dumps(summary(rec), indent=2) + "\n")
    except OSError as exc:
        raise InputError(f"{path}: cannot write: {exc.strerror}") from None
    written.append(path)
    return written
