"""What a sweep runs: a protocol, its points (grid or Latin hypercube) and seeds, as jobs.

:class:`Target` is one protocol file with its fixed ``--set`` overrides,
resolved once (the index keys take their lists from it, the run ids its
identity), and the rig its runs use (:class:`~ffexp.sweeps.rigs.StudyRig`; ``None``:
the built-in rig, whose run ids are those of studies before they took a rig).
:func:`grid` and :func:`latin_hypercube` make the points;
:meth:`Target.check` validates a point against the protocol and scene models
before anything runs; :meth:`Target.job` turns a point and a seed into the
:class:`~ffexp.sweeps.worker.Job` a worker runs.
"""

from __future__ import annotations

import hashlib
import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ffexp.errors import ConfigError
from ffexp.sweeps.keys import Key, Value, current_value, point_overrides, run_id, toml_text
from ffexp.sweeps.worker import Job

if TYPE_CHECKING:
    from ffexp.sweeps.rigs import StudyRig

Point = dict[str, Value]


@dataclass
class Target:
    """One protocol file, its fixed overrides and its resolved models, on a rig."""

    protocol_path: Path
    fixed: tuple[str, ...] = ()
    label: str = ""
    rig: StudyRig | None = None
    """The rig of every run (``None``: the built-in rig). Part of the identity when given;
    the scene is then the one its robot runs in."""
    protocol: Any = field(init=False, repr=False)
    scene: Any = field(init=False, repr=False)
    ident: str = field(init=False)
    seed: int = field(init=False)

    def __post_init__(self) -> None:
        from drivers.description.scene import load_scene
        from ffexp.protocol import load_run_protocol, scene_path

        self.protocol = load_run_protocol(self.protocol_path, self.fixed)
        scene_file = scene_path(self.protocol_path, self.protocol)
        self.seed = int(self.protocol.seed)
        if self.rig is None:
            self.scene = load_scene(scene_file, self.protocol.scene.set)
        else:
            from ffexp.experiment import check_arm

            self.scene = self.rig.scene(scene_file, self.protocol.scene.set, self.seed)
            check_arm(self.rig.model, self.rig.name, self.scene, str(scene_file))
        digest = hashlib.sha1(usedforsecurity=False)
        digest.update(self.protocol.model_dump_json(exclude={"scene"}).encode())
        digest.update(self.scene.model_dump_json().encode())
        if self.rig is not None:  # without one, the identity (and run ids) of before
            digest.update(self.rig.identity().encode())
        self.ident = f"{self.protocol.name}:{digest.hexdigest()[:12]}"
        if not self.label:
            self.label = self.protocol.name

    def overrides(self, keys: Sequence[Key], point: Mapping[str, Value]) -> list[str]:
        """The ``--set`` overrides of a point (the fixed ones first)."""
        return [
            *self.fixed,
            *point_overrides(
                keys, point, self.protocol.model_dump(mode="json"),
                self.scene.model_dump(mode="json"), list(self.protocol.scene.set),
            ),
        ]

    def check(self, keys: Sequence[Key], point: Mapping[str, Value], option: str) -> None:
        """Validate a point against the protocol and scene models (one-line ConfigError
        naming ``option``, the key and what is wrong)."""
        from drivers.description.scene import load_scene
        from ffexp.protocol import load_run_protocol, scene_path

        shown = " ".join(f"{k}={toml_text(v)}" for k, v in point.items())
        try:
            sets = self.overrides(keys, point)
            proto = load_run_protocol(self.protocol_path, sets)
            scene_file = scene_path(self.protocol_path, proto)
            if self.rig is None:
                load_scene(scene_file, proto.scene.set)
            else:
                self.rig.scene(scene_file, proto.scene.set, self.seed)
        except ConfigError as exc:
            where = f"{exc.field}: " if exc.field else ""
            raise ConfigError(option, shown, f"{where}{exc.message}") from None

    def job(self, keys: Sequence[Key], point: Mapping[str, Value], seed: int,
            out_dir: Path, inputs: Path) -> Job:
        """The job of one (point, seed); ``inputs`` is this target's snapshot folder."""
        columns: dict[str, Any] = {k.text: _column_value(point[k.text]) for k in keys}
        rig, rig_overrides, driver = (None, (), None) if self.rig is None else \
            self.rig.job_rig(inputs)
        return Job(
            run_id=run_id(self.ident, point, seed, self.fixed),
            protocol=str(inputs / "protocol.toml"),
            overrides=(*self.overrides(keys, point), 'scene.file="scene.toml"', f"seed={seed}"),
            out_dir=str(out_dir),
            columns={"target": self.label, "rig": self.rig_name, **columns, "seed": seed},
            rig=rig, rig_overrides=rig_overrides, driver=driver,
        )

    @property
    def rig_name(self) -> str:
        """The rows' ``rig``: the rig file as given, or ``<built-in DRIVER rig>``."""
        from ffexp.sweeps.rigs import BUILTIN

        return BUILTIN if self.rig is None else self.rig.name

    def snapshot(self, inputs_root: Path) -> Path:
        """Copy the protocol, its scene and the rig's files into ``inputs_root/<id>/`` (what
        the workers read: the sweep does not depend on the files changing under it)."""
        from ffexp.protocol import scene_path

        folder = inputs_root / self.ident.replace(":", "-")
        folder.mkdir(parents=True, exist_ok=True)
        for name, src in (("protocol.toml", self.protocol_path),
                          ("scene.toml", scene_path(self.protocol_path, self.protocol))):
            data = src.read_bytes()
            dst = folder / name
            if not dst.exists() or dst.read_bytes() != data:
                tmp = folder / f".{name}.tmp"
                tmp.write_bytes(data)
                tmp.replace(dst)
        if self.rig is not None:
            self.rig.copy_into(folder)
        return folder


def _column_value(v: Value) -> Any:
    return toml_text(v) if isinstance(v, list) else v


def grid(axes: Sequence[tuple[Key, Sequence[Value]]]) -> list[Point]:
    """The full product of the values, the first key varying slowest."""
    names = [k.text for k, _ in axes]
    return [dict(zip(names, combo, strict=True))
            for combo in itertools.product(*(vals for _, vals in axes))]


def latin_hypercube(
    ranges: Sequence[tuple[Key, float, float]], n: int, seed: int = 0
) -> list[Point]:
    """``n`` points of a Latin hypercube over the ranges (scipy.stats.qmc), values
    rounded to 6 significant digits (readable overrides; far below any effect)."""
    from scipy.stats import qmc

    if n < 1:
        raise ConfigError("--sample", str(n), "must be at least 1")
    unit = qmc.LatinHypercube(d=len(ranges), seed=seed).random(n)
    lo = [r[1] for r in ranges]
    hi = [r[2] for r in ranges]
    scaled = qmc.scale(unit, lo, hi)
    return [{r[0].text: float(f"{x:.6g}") for r, x in zip(ranges, row, strict=True)}
            for row in scaled]


def seeds_of(target: Target, n: int) -> list[int]:
    """``n`` noise seeds: the protocol's own seed and the next ones."""
    if n < 1:
        raise ConfigError("--seeds", str(n), "must be at least 1")
    return [target.seed + k for k in range(n)]


def check_keys(target: Target, keys: Sequence[Key], options: Mapping[str, str]) -> None:
    """Raise a ConfigError naming a key's option (``options[key.text]``) when the
    target's protocol or scene has no such key (or list element); else return."""
    proto = target.protocol.model_dump(mode="json")
    scene = target.scene.model_dump(mode="json")
    for key in keys:
        try:
            current_value(key, proto, scene)
        except ConfigError as exc:
            raise ConfigError(options.get(key.text, "--vary"), key.text, exc.message) from None
