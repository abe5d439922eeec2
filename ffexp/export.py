"""Tables out of a recording (``ffexp export``): one file per topic, Parquet or CSV.

Each table is the topic's frame (:mod:`ffexp.recording.frames`): ``t_s`` (seconds
from the run start), ``log_time_ns``, then one column per field, array fields
split into one column per element, named by :func:`element_names` from the topic
registry's field metadata (its element count and unit): a wrench
``wrench_fx_n .. wrench_tz_nm``, a twist ``twist_vx_mps .. twist_wz_radps``,
per-axis gains ``stiffness_x_npm .. stiffness_rz_nmprad``, a 4x4 pose
``pose_x_m, pose_y_m, pose_z_m`` for its translation and ``pose_r00 .. pose_r33``
for the rest, seven joints ``joint_pos_j1_rad .. j7_rad``, anything else
``name_k`` with its unit; a scalar field gets its unit too (``f_z_n``), and a
field the registry does not know keeps ``name_k``. Files are named after the topic, slashes turned
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
from ffexp.linkcheck import fault_topics
from ffexp.recording import Recording

FORMATS = ("parquet", "csv")
#: A unit as it goes into a column name (the conventions' suffixes: ``force_n``,
#: ``speed_mps``, ``stiffness_npm_nmprad``); a unit not listed is slugged as it is.
UNIT_SUFFIX = {"N": "n", "N m": "nm", "m/s": "mps", "rad/s": "radps", "N/m": "npm",
               "N m/rad": "nmprad", "m": "m", "rad": "rad", "s": "s", "ns": "ns",
               "kg m^2": "kgm2", "degC": "degc"}
#: The axes of a six-vector, by its units (docs/conventions.md "Frames and axes").
SIX_AXES = {("N", "N m"): ("fx", "fy", "fz", "tx", "ty", "tz"),
            ("m/s", "rad/s"): ("vx", "vy", "vz", "wx", "wy", "wz")}
GAIN_AXES = ("x", "y", "z", "rx", "ry", "rz")


def _suffix(unit: str) -> str:
    unit = unit.strip()
    if not unit:
        return ""
    slug = UNIT_SUFFIX.get(unit) or "".join(c for c in unit.lower() if c.isalnum())
    return f"_{slug}"


def element_names(name: str, count: int, unit: str) -> list[str]:
    """The columns of a field of ``count`` elements in ``unit`` (the registry's
    :class:`~ffexp.recording.schema.FieldSpec`); see the module's description."""
    units = [u.strip() for u in unit.split(",")] if unit else [""]
    if count == 1:  # a name that says its unit already keeps it once (``cycle_s``)
        return [name if name.endswith(_suffix(unit)) else f"{name}{_suffix(unit)}"]
    if count == 6 and len(units) in (1, 2):
        lin, ang = (units[0], units[-1])
        axes = SIX_AXES.get((lin, ang), GAIN_AXES)
        return [f"{name}_{a}{_suffix(lin if k < 3 else ang)}" for k, a in enumerate(axes)]
    if count == 16 and units == ["m"]:  # a 4x4 homogeneous pose, row-major
        return [f"{name}_{'xyz'[r]}_m" if c == 3 and r < 3 else f"{name}_r{r}{c}"
                for r, c in (divmod(k, 4) for k in range(16))]
    if count == 7 and len(units) == 1:  # the arm's seven joints
        return [f"{name}_j{k + 1}{_suffix(unit)}" for k in range(7)]
    one = _suffix(unit) if len(units) == 1 else ""
    return [f"{name}_{k}{one}" for k in range(count)]


def column_names(topic: str, columns: Sequence[str]) -> dict[str, str]:
    """For a CDR topic of the registry: each frame column (``name``, ``name_k``) to its
    named column; other topics, and fields whose element count differs from the
    registry's (an older recording), keep theirs."""
    from ffexp.recording.topics import CDR_TOPICS

    known = CDR_TOPICS.get(topic)
    if known is None:
        return {}
    have = set(columns)
    out: dict[str, str] = {}
    for f in known.spec.fields:
        old = [f.name] if f.count == 1 else [f"{f.name}_{k}" for k in range(f.count)]
        if not all(c in have for c in old) or (f.count > 1 and f"{f.name}_{f.count}" in have):
            continue
        out.update(zip(old, element_names(f.name, f.count, f.unit), strict=True))
    kept = have - set(out)
    if len(set(out.values())) < len(out) or kept & set(out.values()):
        return {}  # names that would collide: the frame's own, unambiguous ones
    return out
#: The file beside the tables that says whether the run's end is in them.
SUMMARY_FILE = "recording.json"
#: What :func:`summary` reads besides the exported topics (the link's verdict: its
#: faults are on the topics the back-ends name, :func:`ffexp.linkcheck.fault_topics`).
SUMMARY_TOPICS = ("/runner/phase", "/robot/state", "/estimator/state", *fault_topics(),
                  "/events")


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
        df = df.rename(columns=column_names(topic, list(df.columns)))
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
